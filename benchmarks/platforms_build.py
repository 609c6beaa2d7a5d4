"""What ``overcon build --platforms all`` costs: the paper's 20 scenes (mechanisms/*_wo*.toml) built
native-only and with every platform (FMI 2.0 and 3.0), without the reference simulations (they run
the same FMU whatever it carries), and the one-off compilation of the per-platform binaries.

Prints, per FMI version: the wall time of the first ``--platforms all`` build (compiling what the
cache lacks: with ``--cold``, an empty cache and an empty zig cache, so every platform's binary
and zig's C libraries are compiled), then the best of ``--repeat`` native-only and cached
``--platforms all`` builds (interleaved), their ratio, and the size of one FMU each way.

    python benchmarks/platforms_build.py [--cold] [--repeat N]

Needs ``pip install 'overcon[platforms]'``. ``--cold`` sets OVERCON_CACHE_DIR and
ZIG_GLOBAL_CACHE_DIR to fresh temporary folders (minutes: zig builds glibc stubs, the MinGW C runtime
and libSystem stubs once per target).
"""
import argparse
import os
import tempfile
import time
from pathlib import Path

from overcon.fmu.build import build_all


def timed_build(scenes, out, fmi, platforms):
    t0 = time.perf_counter()
    code, res = build_all([str(s) for s in scenes], out, refs=False, fmi=fmi, platforms=platforms,
                          allow_nonunique=True, echo=lambda s: None)
    secs = time.perf_counter() - t0
    assert code == 0, f"build exit {code}"
    return secs, res


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mechanisms", default="mechanisms", help="directory of the paper's scenes")
    p.add_argument("--cold", action="store_true", help="start from empty overcon and zig caches")
    p.add_argument("--repeat", type=int, default=2, help="best of N for the native and cached builds")
    args = p.parse_args()
    scenes = sorted(Path(args.mechanisms).glob("*_wo*.toml"))
    with tempfile.TemporaryDirectory() as tmp:
        if args.cold:
            os.environ["OVERCON_CACHE_DIR"] = str(Path(tmp) / "overcon_cache")
            os.environ["ZIG_GLOBAL_CACHE_DIR"] = str(Path(tmp) / "zig_cache")
        print(f"{len(scenes)} scenes, cpus {os.cpu_count()}, cold caches: {args.cold}")
        print("| FMI | native only (s) | --platforms all, first (s) | --platforms all, cached (s) | cached / native "
              "| one FMU native / all (KiB) |")
        print("|---|---|---|---|---|---|")
        timed_build(scenes[:1], Path(tmp) / "warm", 2, "native")  # imports and first calls out of the figures
        for fmi in (2, 3):
            first, res_all = timed_build(scenes, Path(tmp) / f"a{fmi}", fmi, "all")
            nat, cached = [], []
            for k in range(args.repeat):  # interleaved: a machine whose load changes shifts both alike
                nat.append(timed_build(scenes, Path(tmp) / f"n{fmi}_{k}", fmi, "native")[0])
                cached.append(timed_build(scenes, Path(tmp) / f"c{fmi}_{k}", fmi, "all")[0])
            nat, cached = min(nat), min(cached)
            _, res_nat = timed_build(scenes[:1], Path(tmp) / f"s{fmi}", fmi, "native")
            size_nat = res_nat[0].fmu.stat().st_size // 1024
            size_all = next(r for r in res_all if r.name == res_nat[0].name).fmu.stat().st_size // 1024
            print(f"| {fmi}.0 | {nat:.1f} | {first:.1f} | {cached:.1f} | {cached / nat:.2f} | {size_nat} / {size_all} |")


if __name__ == "__main__":
    main()
