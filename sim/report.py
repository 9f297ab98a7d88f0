"""The text report of a torque replay (the ``ctp simulate`` output): object motion and contacts.

:func:`format_report` prints a :class:`sim.torque_replay.SimulationResult`: the object
displacement ``dr`` in the paper's coordinates (2-D ``(dx, dy, dtheta)``, 3-D ``(dp, w)``, eq.
30-32), its direction and, given the requested direction, the cosine to it; and one row per scene
contact with the observed state (stick, slide, separate), forces, slip, travel and final gap,
against the combination's expected state when there is one.
"""

from __future__ import annotations

from analysis._types import Array
from sim.torque_replay import SimulationResult


def format_report(result: SimulationResult, direction: Array | None = None) -> str:
    """A readable summary (the ``ctp simulate`` output); with ``direction`` ``(D,)`` (e.g. the
    DAFC direction the torques were chosen for) also the cosine between it and ``dr``."""
    names = ["dx", "dy", "dtheta"] if result.dim == 2 else ["dx", "dy", "dz", "wx", "wy", "wz"]
    lines = [
        f"simulated {result.duration:.4g} s"
        + (" (stopped early: moved the requested distance)" if result.stopped_early else ""),
        "object dr   " + "  ".join(f"{n}={v:+.4g}" for n, v in zip(names, result.dr, strict=True)),
        "direction   " + "  ".join(f"{v:+.4f}" for v in result.direction),
    ]
    if direction is not None:
        lines.append(f"cosine      {result.cosine(direction):+.4f} to the requested direction")
    lines += [
        f"|dr| rate   {result.speed():.4g} per s",
        "dropped     " + (f"YES ({result.drop_reason})" if result.dropped else "no"),
        "joints dq   " + "  ".join(f"{v:+.4g}" for v in result.dq),
        "",
    ]
    has_comb = result.combination is not None
    w = max([4, *(len(c.body) for c in result.contacts)])
    header = f"{'#':>2}  {'body':<{w}}"
    if has_comb:
        header += f" {'exp':>3}"
    header += (
        f" {'observed':<9} {'mean n':>9} {'max n':>9} {'loaded':>6} {'slip':>10} {'travel':>10} {'gap':>10}"
        "  mean force (world)      "
    )
    if has_comb:
        header += "  ok"
    lines.append(header)
    lines.append("-" * len(header))
    for c in result.contacts:
        row = f"{c.index:>2}  {c.body:<{w}}"
        if has_comb:
            row += f" {c.expected or '':>3}"
        force = "(" + ", ".join(f"{v:+.3g}" for v in c.mean_force) + ")"
        row += (
            f" {c.observed:<9} {c.mean_normal_force:>9.4g} {c.max_normal_force:>9.4g} "
            f"{c.loaded_fraction:>6.0%} {c.slip:>10.3g} {c.travel:>10.3g} {c.final_gap:>10.3g}  {force:<24}"
        )
        if has_comb:
            row += "  " + ("yes" if c.agrees else "NO")
        lines.append(row)
    if result.extra_contacts:
        lines.append("")
        lines.append(
            "other bodies touching the object: "
            + ", ".join(f"{n} (mean normal force {f:.3g})" for n, f in result.extra_contacts)
        )
    if has_comb:
        lines.append("")
        lines.append(
            f"combination {result.combination}: " + ("all contacts agree" if result.agrees else "contacts DISAGREE")
        )
    return "\n".join(lines)


__all__ = ["format_report"]
