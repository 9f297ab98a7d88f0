"""Request and response bodies: one family per resource (``XCreate`` in, ``XPublic`` out)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from analysis.detect import DEFAULT_MU, DEFAULT_TOLERANCE
from analysis.scene import MAX_MAGNITUDE, Scene
from planner.goals import Goal
from planner.options import PlannerOptions

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
JobStatus = Literal["queued", "running", "succeeded", "failed", "cancelled"]


def _check_files(scene: Any) -> Any:
    """A scene sent over HTTP may name URDF and mesh files only inside the installed
    example-robot-data package (``example-robot-data:...``) or an uploaded robot
    (``robot:<sha256>/...``, ``POST /robots``): a request must not read arbitrary server files."""
    if isinstance(scene, dict):
        for i, f in enumerate(scene.get("fingers") or []):
            if isinstance(f, dict) and isinstance(f.get("urdf"), dict):
                file = f["urdf"].get("file")
                if isinstance(file, str) and (not file.startswith(("example-robot-data:", "robot:"))
                                              or ".." in file):
                    raise ValueError(f"fingers.{i}.urdf.file: over HTTP a URDF must be "
                                     f"'example-robot-data:<path>' or 'robot:<sha256>/<path>' (got '{file}')")
                if f["urdf"].get("package_dirs"):
                    raise ValueError(f"fingers.{i}.urdf.package_dirs: not accepted over HTTP")
        shape = (scene.get("object") or {}).get("shape") if isinstance(scene.get("object"), dict) else None
        file = shape.get("file") if isinstance(shape, dict) else None
        if isinstance(file, str) and (not file.startswith(("example-robot-data:", "robot:")) or ".." in file):
            raise ValueError("object.shape.file: over HTTP a mesh must be 'example-robot-data:<path>' or "
                             f"'robot:<sha256>/<path>' (got '{file}')")
    return scene


class _In(BaseModel):
    model_config = ConfigDict(extra="forbid")

    @field_validator("scene", mode="before", check_fields=False)
    @classmethod
    def _scene_files(cls, v: Any) -> Any:
        return _check_files(v)


#: Bounds of ``AnalysisCreate.samples``.
MIN_SAMPLES, MAX_SAMPLES = 8, 720


class AnalysisCreate(_In):
    """``combination`` given: the full report of that combination (``direction`` picks the motion
    for the torque set, ``nu`` adds the friction-uncertainty check). Otherwise: every combination."""

    scene: Scene
    #: one letter per contact: any number of contacts (the route checks the scene's count)
    combination: Annotated[str, Field(min_length=1, max_length=1024, pattern=r"^[FNSDfnsd]+$")] | None = None
    direction: Annotated[list[FiniteFloat], Field(min_length=3, max_length=6)] | None = None
    nu: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] | None = None
    samples: Annotated[int, Field(ge=MIN_SAMPLES, le=MAX_SAMPLES)] | None = Field(
        None, description="with combination: directions of the motion space the DAFC set samples (then refined "
                          "near its boundary). Default: 120 up to a 3-dimensional motion space, 48 beyond; fewer "
                          "answer faster with a coarser DAFC set (a quick report)")


class AnalysisPublic(BaseModel):
    scene: str
    dim: int
    kind: Literal["combination", "enumeration"]
    elapsed_seconds: float
    report: dict[str, Any] | None = Field(None, description="kind=combination: the full report")
    combinations: list[dict[str, Any]] | None = Field(None, description="kind=enumeration: one row each")
    feasible: int | None = None
    semantics: dict[str, str] | None = None
    stats: dict[str, int] | None = None


class PlannerSwitches(_In):
    """The planner's optional kinds of edges (``planner.options.PlannerOptions``; ``ctp plan``'s
    flags of the same names). Each adds states to the search, so each is off unless asked; and the
    weight of the effort term in the edge costs (null: the planner's default)."""

    sliding_motions: Annotated[bool | None, Field(strict=True)] = Field(
        None, description="object motions in which the contacts on fixed bodies slide (S) while the fingers "
                          "stick: null for pose and displacement goals only, true always, false never "
                          "(a sphere on a table then only rolls)")
    link_sliding: Annotated[bool, Field(strict=True)] = Field(
        False, description="object motions towards a goal pose in which the contacts of an arm's distal link "
                           "slide along the object's faces (S at links)")
    link_replacement: Annotated[bool, Field(strict=True)] = Field(
        False, description="lay a link an arm let go of flat on a face of a box object again, the other arms "
                           "pinned")
    contact_slides: Annotated[bool, Field(strict=True)] = Field(
        False, description="slide a link's contact along a face of a box object while the other contacts hold "
                           "it still (eq. 33 with an S-point)")
    separate_finger_contacts: Annotated[bool, Field(strict=True)] = Field(
        False, description="object motions may also separate single finger contacts, not only those on fixed "
                           "bodies")
    effort_weight: Annotated[float, Field(ge=0, allow_inf_nan=False, strict=True)] | None = Field(
        None, description="weight of a transition's effort (|joint torques|, N m) in its cost, >= 0; null: the "
                          f"planner's default {PlannerOptions().effort_weight:g} (0: the cheapest plan by motions and "
                          "contacts only, e.g. a sphere rolled on a link's side rather than pushed by a fingertip)")


class PlanCreate(_In):
    scene: Scene
    goal: Goal
    options: PlannerSwitches | None = Field(
        None, description="optional kinds of planner edges (as `ctp plan`'s flags); omitted: the defaults")
    time_limit: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = Field(
        None, description="seconds; default and maximum: the server's job_time_limit")
    replay: Annotated[bool, Field(strict=True)] = Field(
        False, description="true: after planning, the job replays the plan in one continuous MuJoCo "
                           "simulation (as `ctp simulate`) within what is left of the time limit; the result's "
                           "`replay` holds the simulated object path, each step's planned and simulated "
                           "displacements, the final position (m) and rotation (rad) errors and whether the "
                           "object was dropped, or the replay's own failure")


class EnumerationCreate(_In):
    """Every combination of a scene as a job (for scenes too large for ``POST /analyses``)."""

    scene: Scene
    time_limit: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None


class JobPublic(BaseModel):
    id: str
    kind: str
    status: JobStatus
    progress: float = Field(description="0..1")
    message: str
    error: str | None = Field(None, description="why the job failed")
    created_at: float = Field(description="Unix time")
    started_at: float | None
    finished_at: float | None
    elapsed_seconds: float | None = Field(description="running time so far, or in total")
    queued_seconds: float | None
    attempts: int
    result_url: str | None = Field(description="set once the job succeeded")
    url: str


class PlanPublic(JobPublic):
    pass


class EnumerationPublic(JobPublic):
    pass


class JobList(BaseModel):
    items: list[JobPublic]
    count: int


class ExampleScene(BaseModel):
    name: str
    file: str
    dim: int
    contacts: int
    description: str
    scene: dict[str, Any]


class ContactsCreate(BaseModel):
    """A scene whose contacts are to be found from its geometry (any ``contacts`` it has are
    replaced), the distance ``tolerance`` within which surfaces touch (scene units) and the
    friction ``mu`` of contacts on bodies that name none."""

    model_config = ConfigDict(extra="forbid")
    scene: dict[str, Any]
    tolerance: Annotated[float, Field(gt=0, le=MAX_MAGNITUDE, allow_inf_nan=False)] = DEFAULT_TOLERANCE
    mu: Annotated[float, Field(ge=0, le=MAX_MAGNITUDE, allow_inf_nan=False)] = DEFAULT_MU
    touch: Annotated[list[Annotated[str, Field(min_length=1, max_length=200)]], Field(max_length=32)] = Field(
        default_factory=list, description="links to place on the object first (as `ctp contacts --touch`): the "
        "configuration moves, within joint limits, until each touches it without penetration")

    @field_validator("scene", mode="before")
    @classmethod
    def _scene_files(cls, v: Any) -> Any:
        return _check_files(v)


class DetectedContactPublic(BaseModel):
    body: str
    point: list[float]
    normal: list[float]
    mu: float
    gap: float


class NearMissPublic(BaseModel):
    body: str
    distance: float
    object_point: list[float]
    body_point: list[float]


class ContactsPublic(BaseModel):
    """The complete scene (its ``contacts`` those found), each contact with its gap, and the
    near misses (bodies closer than 10 tolerances that do not touch)."""

    scene: dict[str, Any]
    contacts: list[DetectedContactPublic]
    near_misses: list[NearMissPublic]
    tolerance: float


class GeometryCreate(_In):
    scene: Scene
    configurations: Annotated[list[list[FiniteFloat]], Field(max_length=2000)] | None = Field(
        None, description="joint vectors q (whole hand, scene order); default: the scene's q")


class Health(BaseModel):
    status: Literal["ok"]
    version: str
    database: str
    executor: str
    analysis_workers: int
    job_workers: int
    store: Literal["ok"] = "ok"
    jobs: dict[str, int]


class ErrorItem(BaseModel):
    loc: list[str | int]
    msg: str
    type: str


class ErrorBody(BaseModel):
    detail: str
    errors: list[ErrorItem] = []
    limit: float | None = None
    store: Literal["unavailable"] | None = Field(None, description="503: the job store is unavailable")
