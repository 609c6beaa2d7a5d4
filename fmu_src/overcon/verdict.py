"""How the eliminations of a scene group are compared: settings, tolerances and labels.

Engine-free (standard library only), so that the fmpy tooling (:mod:`overcon.tooling`) and the
in-process paper runs (:mod:`overcon.paper`) share one definition without the tooling importing
the engine.

The observed verdict ("is the motion unique?")
-----------------------------------------------
Two eliminations of one friction set are two different index-1 forms of the equations of motion.
When the friction set is unique (paper Eq. 17) both forms define the *same* function
``y' = f(t, y)``, up to round-off in solving different linear systems; otherwise they define
different functions and the motions part by a physical amount (0.3-0.6 m in the paper groups).

Integrated with an adaptive step-size control, two variants of a unique group do not take the same
steps: the error estimates differ at round-off level, an accept/reject decision flips, and from
then on the variants differ by their integration error (measured 4e-8 to 1e-7 m at tolerance
1e-9), whose size depends on the machine's floating-point luck (BLAS kernel). A verdict drawn from
such runs has a thin margin and is not reproducible across machines.

So the verdict runs are **lockstep** runs: every variant is integrated with the same fixed-step
method on the same grid, :data:`LOCKSTEP_METHOD` (classical Runge-Kutta 4) with step
:data:`LOCKSTEP_STEP` (5 ms unless given). Identical step sequences leave only round-off,
amplified by the dynamics: measured at most 8e-13 m on the paper's unique groups (planar f45:
9e-16 m, spatial M, N: 8e-13 m over 10 s), while the non-unique groups differ by >= 0.3 m. The
threshold :func:`lockstep_tolerance` = :data:`LOCKSTEP_FACTOR` x max(1, scale) = 1e-8 (m or rad for
outputs of magnitude <= 1) lies four decades above that round-off and five below the smallest
non-unique difference: no round-off pattern of any CPU moves a verdict, and a change of 1e-6 m
in any position is still caught.

The lockstep grid does not need to be accurate for the verdict: both variants carry the same
truncation error, and whether their functions f agree does not depend on the step. It must be
*stable*, though: beyond rk4's stability boundary (e.g. sticking friction inside a small
regularisation band) the fixed-step solution chatters, and the chatter amplifies round-off like a
chaotic map, so a unique group would look non-unique. The rk4 integrator refuses such a step
(core/integrate_rk.c's unstable-step status, whose ``stable_step`` names a stable step, as data: in
process on the ``SimulationError``, from an FMU as its variable ``solver.stable_step`` read after
the failed run). :class:`LockstepGrid` is the one procedure every comparison follows (``compare``,
``reproduce``, ``sweep``, ``figures``): it repeats the group's lockstep runs at
:func:`next_lockstep_step`, at most :data:`LOCKSTEP_RETRIES` times, every variant on the same new
grid, and reports the step it used. Its remaining
error against the adaptive runs is reported, not hidden (rk4 at 5 ms on the paper scenes: 1e-5 m
for planar friction 4, 5; up to 6e-4 m for friction 1, 4, 5, where sticking makes the
right-hand side kink). The adaptive runs (the FMUs' own settings, used for the figures) are
compared too and their largest difference is reported beside the verdict as a second figure,
never deciding.

FMUs of other tools (no ``solver.method``/``solver.step`` parameters) cannot be run in lockstep;
their verdict falls back to the adaptive runs with :func:`uniqueness_tolerance`, and the report
says so.
"""
from __future__ import annotations


LOCKSTEP_METHOD = "rk4"
"""Fixed-step method of the verdict runs (see the module docstring)."""

LOCKSTEP_STEP = 5e-3
"""Default step of the verdict runs (s): stable and well resolved on every paper scene (friction
sticking included), 2 to 4 times the cost of an adaptive run at tolerance 1e-9."""

LOCKSTEP_UNSTABLE = "rk4 is unstable"
"""The words that open the rk4 integrator's unstable-step message (for people; the comparison
reads the stable step as data, :class:`LockstepGrid`)."""

LOCKSTEP_RETRIES = 3
"""How many times a group's lockstep runs are repeated with a smaller step after an unstable step."""

LOCKSTEP_MIN_STEP = 1e-6
"""Smallest lockstep step (s), also the lower bound of ``--lockstep-step``."""

LOCKSTEP_FACTOR = 1e-8
"""Lockstep verdict threshold relative to max(1, scale) (see :func:`lockstep_tolerance`)."""

UNIQUE_FACTOR = 100.0
"""Adaptive-run threshold factor (fallback verdict for FMUs that cannot run in lockstep)."""


def lockstep_tolerance(scale: float) -> float:
    """Largest difference between lockstep runs of two eliminations still called "unique":
    1e-8 x max(1, scale), scale = max |y| of the output (m or rad)."""
    return LOCKSTEP_FACTOR * max(1.0, scale)


def uniqueness_tolerance(solver_tolerance: float, scale: float) -> float:
    """Adaptive runs only (fallback): 100 x the integration tolerance x max(1, scale).

    Why 100: dopri5 controls the local error per step; its global error over a paper run,
    measured against a 1e-12 reference, is 20-100 x tolerance x scale, and two variants whose
    adaptive step sequences diverge differ by up to that much although the motion is unique. This
    margin is thin (a factor 2.6 on the paper groups) and machine dependent, which is why verdicts
    come from lockstep runs wherever the FMU allows them."""
    return UNIQUE_FACTOR * solver_tolerance * max(1.0, scale)


def equation_joints(joints) -> list[str]:
    """The joint name of every constraint equation, in equation order, from a compiled model's
    joints (``Model.joints``: each with ``name`` and its 0-based ``rows``)."""
    owner: dict[int, str] = {}
    for c in joints:
        for r in c.rows:
            owner[int(r)] = c.name
    return [owner.get(k, "") for k in range(max(owner, default=-1) + 1)]


def variant_label(eliminate, equation_joints=()) -> str:
    """Legend label as in the paper, with the joint whose equations are eliminated: "without eq. 4
    of joint2", "without eq. 3, 4, 5 of A, eq. 9, 10 of B" (``eliminate``: 1-based equation numbers,
    ``"auto"``, or empty; ``equation_joints``: the joint of every equation, in order; without it,
    or for a number outside it, the numbers alone: "without eq. 4")."""
    if eliminate == "auto":
        return "auto elimination"
    if not eliminate:
        return "no elimination"
    if not all(1 <= k <= len(equation_joints) for k in eliminate):
        return "without eq. " + ", ".join(str(k) for k in eliminate)
    parts: list[tuple[str, list[int]]] = []
    for k in eliminate:
        joint = equation_joints[k - 1]
        if parts and parts[-1][0] == joint:
            parts[-1][1].append(k)
        else:
            parts.append((joint, [k]))
    return "without " + ", ".join(f"eq. {', '.join(map(str, ks))} of {joint}" for joint, ks in parts)


def next_lockstep_step(step: float, stable_steps: list[float | None]) -> float | None:
    """The step of the repeated lockstep runs after runs at ``step`` failed, given per failed run
    the stable step rk4 named (None: the run failed for another reason): None when a failure is
    not an unstable step (or the step would fall below :data:`LOCKSTEP_MIN_STEP`), else the
    smallest stable step named, and at most a quarter of ``step``, rounded down to one significant
    digit (so every variant gets the same grid)."""
    if not stable_steps or any(h is None or not h > 0.0 for h in stable_steps):
        return None
    h = min([step / 4.0, *stable_steps])
    if not h > 0.0:
        return None
    e = 10.0 ** int(f"{h:e}".split("e")[1])
    h = int(h / e) * e
    return h if h >= LOCKSTEP_MIN_STEP else None


class LockstepGrid:
    """The lockstep procedure of one group at one set of parameters: the step every variant runs
    with (``step``, s), and the retry. After the variants' runs at ``step``, :meth:`retry` with
    the stable steps their failures named decides whether all of them run again at a smaller
    common step (:func:`next_lockstep_step`, at most :data:`LOCKSTEP_RETRIES` times). The one
    definition used by the in-process figures (:mod:`overcon.paper`), compare and reproduce
    (:mod:`overcon.tooling.pipeline`) and sweep (:mod:`overcon.tooling.sweep`)."""

    def __init__(self, step: float):
        self.asked = float(step)
        self.step = float(step)
        self.retries = 0
        self.named: float | None = None  # the smallest stable step the last failures named

    def retry(self, stable_steps: list[float | None]) -> bool:
        """True when the runs must be repeated: then ``step`` is the new common step."""
        if self.retries >= LOCKSTEP_RETRIES:
            return False
        h = next_lockstep_step(self.step, stable_steps)
        if h is None:
            return False
        self.named = min(stable_steps)
        self.retries += 1
        self.step = h
        return True

    @property
    def note(self) -> str | None:
        """Why the step used differs from the one asked for (None if it does not)."""
        if self.step == self.asked:
            return None
        return (f"rk4 unstable at the lockstep step {self.asked:g} s (a step of at most {self.named:.2g} s is "
                f"stable); lockstep runs repeated at {self.step:g} s")


def lockstep_start_values(step: float) -> dict:
    """FMU parameters that put an overcon FMU on the lockstep grid."""
    return {"solver.method": LOCKSTEP_METHOD, "solver.step": float(step)}
