"""The service's settings: one pydantic-settings class, read from ``CTP_*`` environment variables
(or a ``.env`` file). Every knob of the service lives here."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

PROJECT_DIR = Path(__file__).resolve().parent.parent


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="CTP_", env_file=".env", extra="ignore")

    #: Job store. ``sqlite:///path/jobs.db`` (default, a file next to the working directory) or a
    #: PostgreSQL URL ``postgresql+psycopg://user:pass@host/db`` (same store code, SQLAlchemy Core).
    database_url: str = "sqlite:///ctp-jobs.db"
    #: Worker processes for synchronous analyses (``POST /analyses``).
    analysis_workers: Annotated[int, Field(ge=1, le=64)] = 2
    #: Worker processes reserved for light requests (one combination's analysis, a scene's
    #: geometry), so that they never wait behind tables of every combination; the
    #: ``analysis_workers`` run at a lower CPU priority and lend an idle worker to light requests.
    light_workers: Annotated[int, Field(ge=1, le=64)] = 2
    #: Joints a request's scene may have in all (its geometry costs grow with the chain length).
    max_joints: Annotated[int, Field(ge=1, le=10_000)] = 128
    #: Analyses kept in the content-addressed result cache (0: no cache).
    analysis_cache_entries: Annotated[int, Field(ge=0, le=100_000)] = 1024
    #: Worker processes for jobs (plans, enumerations) when no Ray address is set.
    job_workers: Annotated[int, Field(ge=1, le=64)] = 1
    #: Run jobs as Ray tasks on this cluster (``auto``, ``ray://host:10001``, ``local``); empty: processes.
    ray_address: str | None = None
    #: Wall-clock limit of one synchronous analysis (seconds); past it the worker is stopped.
    request_time_limit: Annotated[float, Field(gt=0)] = 30.0
    #: Default and maximum wall-clock limit of one job (seconds), a total over all its attempts.
    job_time_limit: Annotated[float, Field(gt=0)] = 600.0
    #: Contacts a scene may have for an enumeration of every combination (3**L of them); one
    #: combination and plans take any number.
    max_contacts: Annotated[int, Field(ge=1, le=16)] = 12
    #: Largest request body accepted (bytes).
    max_body_bytes: Annotated[int, Field(ge=1024)] = 1_000_000
    #: JSON bodies of the scene-taking routes up to this size (bytes) are read in the server; a
    #: larger one is decoded and screened (the counts and the model) in a worker first
    #: (:mod:`api.bodies`), so a megabyte of JSON never holds the event loop.
    inline_body_bytes: Annotated[int, Field(ge=0)] = 64_000
    #: A running job whose owner stops heart-beating for this long is taken over by another
    #: runner (the same server after a restart, or another instance).
    job_lease_seconds: Annotated[float, Field(gt=0)] = 30.0
    #: How often the job runner looks for queued work (seconds).
    job_poll_seconds: Annotated[float, Field(gt=0)] = 0.5
    #: How many times a job interrupted by a crash or restart is retried before it fails.
    job_max_attempts: Annotated[int, Field(ge=1)] = 3
    #: How long one store statement waits for a lock (SQLite's busy timeout, PostgreSQL's
    #: lock_timeout) or a new PostgreSQL connection waits, before the request answers 503.
    store_timeout_seconds: Annotated[float, Field(gt=0, le=300)] = 5.0
    #: ``Retry-After`` of a 503 while the store is unavailable (seconds).
    store_retry_after_seconds: Annotated[int, Field(ge=1, le=3600)] = 5
    #: Longest pause between the job runner's retries of a store write (heartbeat, progress, a
    #: job's final state) while the store is unavailable; the pauses double up to it from 0.2 s.
    store_retry_max_seconds: Annotated[float, Field(gt=0, le=300)] = 5.0
    #: The service's data folder (env ``CTP_DATA_DIR``): uploaded robots are kept in its
    #: ``robots/<sha256>/`` folders. The app exports it as ``CTP_DATA_DIR`` to its own process
    #: and its workers, where the analysis resolves ``urdf.file = "robot:<sha256>/<path>"``
    #: (analysis/urdf.py ``resolve_urdf_path``; same default, relative to the working directory).
    data_dir: Path = Path("ctp-data")
    #: Largest robot archive ``POST /robots`` accepts (bytes, the request body).
    max_robot_archive_bytes: Annotated[int, Field(ge=1024)] = 64_000_000
    #: Most bytes the files of one robot archive may take once unpacked, and most files in it.
    max_robot_unpacked_bytes: Annotated[int, Field(ge=1024)] = 256_000_000
    max_robot_files: Annotated[int, Field(ge=1, le=100_000)] = 2_000
    #: Scenes listed by ``GET /scenes/examples``.
    examples_dir: Path = PROJECT_DIR / "examples"
    #: Start the job runner with the app (tests of the API alone may turn it off).
    run_jobs: bool = True


@lru_cache
def get_settings() -> Settings:
    return Settings()
