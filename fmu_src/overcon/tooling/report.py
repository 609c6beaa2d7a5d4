"""Console tables, Markdown reports and PNG plots of :class:`~overcon.tooling.compare.Comparison`s."""
from __future__ import annotations

import re
from pathlib import Path

from .compare import Along, Comparison, Interval, OutputDiff, rules_text


def _g(x: float | None) -> str:
    return "—" if x is None else f"{x:.3g}"


def _unit(d: OutputDiff) -> str:
    return d.unit or ""


MEASURE = "largest difference relative to its tolerance"
"""What the verdict's figure is (decided, issue 37): the deciding output whose largest absolute
difference between the variants is the largest multiple of its own tolerance, the output that
decides the verdict; shown with its unit and tolerance. An output with a larger absolute difference
in a looser tolerance (or another unit) is not that figure: the table lists every output, and the
adaptive runs' figure is given per unit."""


def adaptive_text(c: Comparison) -> str | None:
    """The adaptive runs' largest absolute difference per unit, each with its output, e.g. ``0.012 m
    in slider1.x, 17.2 rad in crank.phi`` (units never mixed in one figure); None without them."""
    if not c.adaptive_diff:
        return None
    unit_of = {d.name: _unit(d) for d in c.diffs}
    best: dict[str, tuple[float, str]] = {}
    for name, value in c.adaptive_diff.items():
        u = unit_of.get(name, "")
        if u not in best or value > best[u][0]:
            best[u] = (value, name)
    return ", ".join(f"{v:.3g}{' ' + u if u else ''} in {n}" for u, (v, n) in sorted(best.items()))


def _second_figure(c: Comparison) -> str:
    if c.adaptive_failure is not None:
        return f"; ADAPTIVE RUN FAILED (verdict from the lockstep runs): {c.adaptive_failure}"
    a = adaptive_text(c)
    if c.mode != "lockstep" or a is None:
        return ""
    return f"; adaptive runs' largest difference (not deciding): {a}"


def verdict_line(c: Comparison) -> str:
    """One line; a mismatch or a failed run is LOUD."""
    if c.invalid:
        return f"!!! NOT COMPARED !!! {c.group}: {c.failure}"
    if c.failure is not None:
        return f"!!! FAILED !!! {c.group}: no verdict, a run failed: {c.failure}"
    w = c.worst()
    how = f" ({c.mode})" if c.reference is None else ""
    worst = (f"; {MEASURE}{how}: {w.max_abs:.3g} {_unit(w)} in {w.name} (tolerance {w.tolerance:.3g} {_unit(w)})"
             f"{_second_figure(c)}" if w else "")
    if c.reference is not None:
        head = f"{c.group}: {c.infos[0].path.name} vs {c.reference}: {c.verdict_text().upper()}"
        return head + worst + ("" if c.observed else "  <-- differs from the reference")
    pred = "none (expected unique)" if c.predicted is None else c.verdict_text(c.predicted)
    head = f"{c.group}: observed {c.verdict_text().upper()}, predicted {pred} (pre-check)"
    if c.not_excited:
        return head + worst + (" -- OK (not excited: friction on a non-unique reaction lets the motion depend on "
                               "the elimination, but these loads do not reach the non-unique part)")
    if c.matches:
        return head + worst + " -- OK"
    return (f"!!! MISMATCH !!! {c.group}: observed {c.verdict_text().upper()} but the pre-check predicted "
            f"{pred}{worst}")


def console_table(c: Comparison) -> str:
    """Every compared output: max abs/rel difference, tolerance, first time over it."""
    if c.failure is not None:
        head = "NOT COMPARED" if c.invalid else "FAILED"
        return "\n".join([f"{c.group}: " + ", ".join(i.model for i in c.infos) + f"\n  {head}: {c.failure}",
                          *_console_along(c)])
    lines = [f"{c.group}: " + (f"{c.infos[0].path.name} vs reference {c.reference}" if c.reference is not None
                              else ", ".join(f"{i.model} ({lab})" for i, lab in zip(c.infos, c.labels)))]
    if c.mode == "lockstep":
        second = (f"FAILED: {c.adaptive_failure}" if c.adaptive_failure is not None else
                  f"largest difference {adaptive_text(c) or '—'} (reported, not deciding)")
        lines.append(f"  verdict from lockstep runs (rk4, step {c.lockstep_step:g} s); adaptive runs: {second}")
        if c.lockstep_note:
            lines.append(f"  {c.lockstep_note}")
    lines.append(f"  {'output':<24} {'unit':<5} {'max abs':>10} {'max rel':>10} {'tolerance':>10} "
                 f"{'first t>tol':>11}  decides")
    for d in c.diffs:
        first = "—" if d.first_exceed is None else f"{d.first_exceed:g} s"
        note = "yes" if d.decides else "no"
        if d.kind == "reaction" and d.reaction_unique is not None:
            note += " (reaction " + ("unique" if d.reaction_unique else "NOT unique") + ")"
        flag = " *" if d.decides and not d.within else ""
        lines.append(f"  {d.name:<24} {_unit(d):<5} {d.max_abs:>10.3g} {_g(d.max_rel):>10} {d.tolerance:>10.3g} "
                     f"{first:>11}  {note}{flag}")
    lines += _console_along(c)
    return "\n".join(lines)


def _console_along(c: Comparison) -> list[str]:
    along = along_lines(c)
    return ["  uniqueness along the motion (discrete outputs, every output point):", *(f"    {ln}" for ln in along)] \
        if along else []


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name)


def shown_runs(c: Comparison, *, deciding: bool = False) -> str:
    """Which runs of ``c`` a plot shows: the adaptive runs (``c.series``), or, when those failed
    or with ``deciding`` in lockstep mode, the lockstep runs."""
    if c.mode == "lockstep" and (deciding or c.adaptive_failure is not None):
        return f"lockstep runs (rk4, step {c.lockstep_step:g} s, identical steps for every variant)"
    return "adaptive runs (each FMU's own solver settings)"


def plot_comparison(c: Comparison, out_dir: Path, outputs: str | list[str] = "worst") -> list[Path]:
    """PNG per selected output (``"worst"``: the deciding output with the largest difference
    relative to its tolerance; ``"all"``: every deciding output; or a list of names): the runs
    that decide the verdict (the lockstep runs in lockstep mode, the title's second line says
    which, and gives the adaptive runs' difference beside it), one line per variant labelled like
    the paper, and a panel of differences to the first one."""
    from ..plots import plot_series

    by_name = {d.name: d for d in c.diffs}
    if c.failure is not None:
        return []
    if outputs == "worst":
        w = c.worst()
        names = [w.name] if w else []
    elif outputs == "all":
        names = [d.name for d in c.diffs if d.decides]
    else:
        names = [n for n in outputs if n in by_name]
    runs = c.lockstep_series if c.mode == "lockstep" and c.lockstep_series else c.series
    shown = shown_runs(c, deciding=True)
    paths = []
    for n in names:
        d = by_name[n]
        series = {lab: s.values[n] for lab, s in zip(c.labels, runs)}
        kind = "reference comparison" if c.reference is not None else c.verdict_text()
        second = (f"\nthe adaptive runs (not shown) differ by {c.adaptive_diff[n]:.3g} {_unit(d)}"
                  if runs is not c.series and n in c.adaptive_diff else "")
        paths.append(plot_series(Path(out_dir) / f"{_safe(c.group)}_{_safe(n)}.png", runs[0].time, series,
                                 title=f"{c.group}: {n} ({kind}; max difference {d.max_abs:.3g} {_unit(d)})",
                                 ylabel=f"{n} ({_unit(d)})" if d.unit else n, runs=shown + second))
    return paths


def _rel(path: Path, base: Path) -> str:
    try:
        return Path(path).resolve().relative_to(Path(base).resolve()).as_posix()
    except ValueError:
        return Path(path).resolve().as_posix()


def summary_rows(comparisons: list[Comparison]) -> list[str]:
    """Markdown table: mechanism, group / friction set, eliminations, predicted, observed, max
    difference, simulation wall time."""
    rows = ["| mechanism | group (friction set) | eliminations | predicted | observed | "
            f"{MEASURE} (output, tolerance, runs) | adaptive runs' largest difference per unit | wall time (s) |",
            "|---|---|---|---|---|---|---|---|"]
    for c in comparisons:
        i0 = c.infos[0]
        fr = ", ".join(i0.friction) if i0.friction else "none"
        elim = "; ".join(i.eliminate_text() or i.model for i in c.infos)
        pred = "—" if c.predicted is None else c.verdict_text(c.predicted)
        if c.invalid:
            obs = "**not compared** (invalid group)"
        elif c.failure is not None:
            obs = "**FAILED** (no verdict)"
        else:
            obs = c.verdict_text() + ("" if c.matches else " **MISMATCH**")
        w = c.worst()
        md = f"{w.max_abs:.3g} {_unit(w)} ({w.name}, {w.tolerance:.2g} {_unit(w)}, {c.mode})" if w else "—"
        second = ("**FAILED**" if c.adaptive_failure is not None else
                  adaptive_text(c) or "—" if c.mode == "lockstep" else "—")
        wall = " + ".join(f"{s:.1f}" for s in c.wall_seconds) if c.wall_seconds else "—"
        rows.append(f"| {i0.mechanism or '—'} | {c.group} ({fr}) | {elim} | {pred} | {obs} | {md} | {second} | {wall} |")
    return rows


def _state(iv: Interval) -> str:
    which = (f"reaction not unique: {', '.join(iv.nonunique)}" if iv.nonunique
             else "friction joints' reactions unique")
    return f"rank {iv.rank}, {which}, motion {'unique' if iv.motion_unique else 'NOT unique'}"


def along_lines(c: Comparison) -> list[str]:
    """Per FMU with the discrete uniqueness outputs, one line: that they stayed as at t = 0, or the
    intervals where the rank differs from t = 0's or a friction joint's reaction (or the motion)
    is not unique (:mod:`overcon.tooling.compare`, rules); [] when no FMU of ``c`` has them."""
    if not any(a is not None for a in c.along):
        return []
    lines = []
    for info, a in zip(c.infos, c.along):
        if a is None:
            lines.append(f"{info.model}: no discrete uniqueness outputs (judged at t = 0 only)")
            continue
        lines.append(f"{info.model}: {_along_text(a)}")
    return lines


def _key(iv: Interval) -> tuple:
    return iv.rank, iv.nonunique, iv.motion_unique


def _along_text(a: Along) -> str:
    i0 = a.initial
    if all(_key(iv) == _key(i0) for iv in a.intervals):
        sampled = [iv for iv in a.intervals if not iv.at_stop] or [i0]
        stop = " and at the run's stop" if a.failed else ""
        return f"stayed as at t = 0 from {i0.start:g} to {sampled[-1].end:g} s{stop}: {_state(i0)}"
    off = a.off()
    head = f"at t = 0 {_state(i0)}; " if off[0] is not i0 else ""
    parts = []
    for iv in off:
        k = a.intervals.index(iv)
        when = (f"at the run's stop (between t = {a.intervals[k - 1].end:g} and {iv.end:g} s)" if iv.at_stop and k
                else f"t = {iv.start:g}..{iv.end:g} s")
        parts.append(f"{when}: {_state(iv)}" + (f" (rank at t = 0: {i0.rank})" if iv.rank != i0.rank else ""))
    return head + "; ".join(parts)


def group_section(c: Comparison, base: Path, plots: list[Path]) -> list[str]:
    lines = [f"### {c.group}", ""]
    along = along_lines(c)
    if along:
        along = ["Uniqueness along the motion (the FMUs' discrete outputs `rank`, `motion_unique`, "
                 "`<joint>.reaction_unique`, sampled at every output point; reported, not deciding):", "",
                 *(f"- {ln}" for ln in along), ""]
    if c.failure is not None:
        variants = ", ".join(f"`{i.model}` ({lab})" for i, lab in zip(c.infos, c.labels))
        why = ("**not compared**: the FMUs do not form a group." if c.invalid else
               "**FAILED**, no verdict: a run did not reach its stop time.")
        return lines + [f"Variants: {variants}. {why}", "", "```", c.failure, "```", "", *along]
    if c.reference is not None:
        lines.append(f"{c.infos[0].path.name} against reference `{c.reference}`: **{c.verdict_text()}**.")
    else:
        variants = ", ".join(f"`{i.model}` ({lab})" for i, lab in zip(c.infos, c.labels))
        pred = "none (expected unique)" if c.predicted is None else c.verdict_text(c.predicted)
        lines.append(f"Variants: {variants}. Predicted (pre-check): {pred}; observed: **{c.verdict_text()}**"
                     + (" — consistent: not excited (the loads of this run do not reach the non-unique part of "
                        "the friction joints' reactions)." if c.not_excited else
                        "." if c.matches else " — **MISMATCH with the prediction**."))
    if c.lockstep_note:
        lines += ["", c.lockstep_note + "."]
    if c.adaptive_failure is not None:
        lines += ["", f"Differences below are from the lockstep runs (rk4, step {c.lockstep_step:g} s, identical steps "
                  "for every variant). The adaptive runs FAILED (no second figure, no plot of them):", "",
                  "```", c.adaptive_failure, "```"]
    elif c.mode == "lockstep":
        lines += ["", f"Differences below are from the lockstep runs (rk4, step {c.lockstep_step:g} s, identical steps "
                  f"for every variant); the adaptive runs' largest difference per unit is {adaptive_text(c) or '—'} "
                  "(reported, not deciding)."]
    lines += ["", "| output | unit | max abs | max rel | tolerance | first t > tol (s) | decides |",
              "|---|---|---|---|---|---|---|"]
    reactions: dict[str, list[OutputDiff]] = {}
    for d in c.diffs:
        if d.kind == "reaction" and not d.decides:
            reactions.setdefault(d.name.rsplit(".", 1)[0], []).append(d)
            continue
        lines.append(f"| {d.name} | {_unit(d)} | {d.max_abs:.3g} | {_g(d.max_rel)} | {d.tolerance:.3g} | "
                     f"{_g(d.first_exceed)} | {'yes' if d.decides else 'no'} |")
    if reactions:
        lines += ["", "Reactions (reported, not deciding): largest component difference per joint.", "",
                  "| joint | reaction unique (pre-check) | component | max abs | max rel | first t > tol (s) |",
                  "|---|---|---|---|---|---|"]
        for joint, ds in reactions.items():
            w = max(ds, key=lambda d: d.max_abs)
            ru = {True: "yes", False: "no", None: "—"}[w.reaction_unique]
            lines.append(f"| {joint} | {ru} | {w.name} | {w.max_abs:.3g} {_unit(w)} | {_g(w.max_rel)} | "
                         f"{_g(w.first_exceed)} |")
    if along:
        lines += ["", *along[:-1]]
    for p in plots:
        lines += ["", f"![{c.group}: {p.stem}]({_rel(p, base)})"]
    lines.append("")
    return lines


def markdown(comparisons: list[Comparison], base: Path, *, title: str, intro: list[str] = (),
             figures: list[tuple[str, Path]] = (), plots: dict | None = None, tail: list[str] = (),
             beyond: list[str] = ()) -> str:
    """The whole report; image links relative to ``base`` (the report's directory). ``beyond``:
    the Markdown lines of the figures beyond the paper, a section after the paper's figures."""
    plots = plots or {}
    n_failed = sum(c.failure is not None for c in comparisons)
    n_bad = sum(not c.matches for c in comparisons) - n_failed
    n_invalid = sum(c.invalid for c in comparisons)
    n_failed -= n_invalid
    head = ("**Every observed verdict equals its prediction.**" if not n_bad else
            f"**{n_bad} verdict(s) differ from the prediction (MISMATCH).**")
    if n_failed:
        head += f" **{n_failed} group(s) FAILED (a run did not finish; no verdict).**"
    if n_invalid:
        head += f" **{n_invalid} group(s) not compared (invalid group).**"
    n_adaptive = sum(c.adaptive_failure is not None for c in comparisons)
    if n_adaptive:
        head += f" **{n_adaptive} group(s): adaptive runs FAILED (verdict from the lockstep runs).**"
    lines = [f"# {title}", "", *intro]
    lines += ["", head, "",
              "## Verdicts", "", *summary_rows(comparisons), "", rules_text(comparisons), ""]
    if figures:
        lines += ["## Figures of the paper", ""]
        for caption, p in figures:
            lines += [f"**{caption}**", "", f"![{caption}]({_rel(p, base)})", ""]
    if beyond:
        lines += ["## Beyond the paper: compliant joints", "",
                  "*Not in the paper.* A paper group whose friction joint has a non-unique reaction, run also with "
                  "compliant joints (`redundancy = \"compliant\"`, issue 24): the joints share their loads by their "
                  "stiffnesses, so the reactions, the friction and the motion are unique again, whatever elimination "
                  "the scene names. Shown beside the rigid eliminations' curves.", "", *beyond]
    lines += ["## Groups", ""]
    for c in comparisons:
        lines += group_section(c, base, plots.get(c.group, []))
    lines += list(tail)
    return "\n".join(lines).rstrip() + "\n"
