#!/usr/bin/env bash
# The C core under AddressSanitizer and UndefinedBehaviorSanitizer (and LeakSanitizer, part of
# ASan on Linux): tests/c_core/make_cases.py writes packed models and the results the installed
# core gives (the paper's planar and spatial mechanisms, the quaternion examples with spatial revolute,
# prismatic, cylindrical and spherical joints, a chain of every spatial joint type, runs with every integrator
# (dopri5, rk4, dop853, radau), damped-Newton states and every failure
# status, and runs stopped by the singularity watch of core/watch.c: a singular position located inside a
# step, an expired and a degrading elimination; formulation AL: evaluations at a singular position, projections
# (ovk_project) and a run passing a singular position), then tests/c_core/driver.c, compiled with the core's sources and the sanitizers, runs
# every case 20 times in two workspaces and requires the same bits, statuses and messages. Any
# out-of-bounds access, leak or undefined behaviour stops it with the sanitizer's report.
# Then the FMI layer of the FMUs without Python (fmu_src/overcon/fmu/native/fmu_*.c and fmi2_*.c over the core),
# compiled with the sanitizers into C-runtime FMUs of a friction scene (also with radau and dop853), a
# quaternion scene, scenes with energy outputs (the Bricard linkage, the compliant door) (every
# FMU's model file also carries the packed models of the redundancy parameter's other methods), 17
# double pendulums with 34 friction joints (beyond the 32 the core once took on its stack: the
# friction solve's buffers sized from the model), a
# parallelogram passing its flat position (solver.singular = "pass" in the model file), run
# by the plain C host (tests/c_host/fmu_host.c, sanitized too) over 0-1 s with
# an FMU state saved half-way through its bytes and restored (-S: the same bits at the end).
# Then the FMI 3.0 layer (fmi3_*.c) the same way through tests/c_host/fmu_host3.c, co-simulation (-S) and
# Model Exchange (-M). Every run also calls ovk_sim_watch_extremes (warm and cold) and checks the state is untouched.
# Then the fuzzing stage (below: FMU states, model files, FMI calls; FUZZ_SECONDS). Also compiles the core with
# clang -Werror when clang is installed. About 40 s plus the fuzzing stage's 90 s.
# Usage: bash ci/sanitize.sh   (PYTHON: the installed overcon's interpreter, default .venv/bin/python;
#                               CC: the compiler, default cc)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
CC=${CC:-cc}
CORE=fmu_src/overcon/core
FLAGS=(-O2 -ffp-contract=off -fno-fast-math -std=c11 -Wall -Wextra -Werror)
SAN=(-g -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

"$PY" tests/c_core/make_cases.py "$tmp/cases.bin"
# shellcheck disable=SC2086
$CC "${FLAGS[@]}" "${SAN[@]}" -I "$CORE" -o "$tmp/driver" tests/c_core/driver.c "$CORE"/*.c -lm
ASAN_OPTIONS=detect_leaks=1:halt_on_error=1:detect_stack_use_after_return=1 \
UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    "$tmp/driver" "$tmp/cases.bin" 20
FMI=fmu_src/overcon/fmu/native
"$PY" - "$tmp/fmus" "$tmp/scenes" <<'PYEOF'
import shutil, sys
from pathlib import Path
from overcon.fmu.build import build_all
scenes = Path(sys.argv[2])  # planar_f45_wo4 with radau (its LU factors in the FMU state) and with dop853
scenes.mkdir()
shutil.copy("mechanisms/planar_sliders.toml", scenes)
text = Path("mechanisms/planar_f45_wo4.toml").read_text()
for method in ("radau", "dop853"):
    (scenes / f"f45_{method}.toml").write_text(text.replace('name = "planar_f45_wo4"', f'name = "f45_{method}"')
                                               .replace("[solver]", f'[solver]\nmethod = "{method}"'))
# the compliant door (core/compliance.c) with dopri5: its radau run is slow under the sanitizers; with
# energy outputs (core/energy.c: the compliant joints' springs and dampers)
(scenes / "compliant_door.toml").write_text(Path("mechanisms/examples/compliant_door.toml").read_text())
(scenes / "compliant_door_h1_wo_hinge2.toml").write_text(
    Path("mechanisms/examples/compliant_door_h1_wo_hinge2.toml").read_text().replace('"radau"', '"dopri5"')
    .replace('friction = "all"\n', 'friction = "all"\nenergy = true\n'))
sys.path.insert(0, "tests")
from test_fmu_c import pendulums  # noqa: E402
from test_singular_pass import parallelogram  # noqa: E402
many, passing = pendulums(17, scenes / "k17"), parallelogram(3, scenes / "pg", 1.0)
code, _ = build_all(["mechanisms/planar_f45_wo4.toml", "mechanisms/examples/door_h1_wo_hinge2.toml",
                     "tests/data/bricard/bricard_wo2.toml", str(scenes / "f45_radau.toml"),
                     str(scenes / "f45_dop853.toml"), str(scenes / "compliant_door_h1_wo_hinge2.toml"),
                     str(many), str(passing)],
                    sys.argv[1],
                    refs=False, validate=False, runtime="c", allow_nonunique=True, echo=lambda s: None)
sys.exit(code)
PYEOF
$CC -O2 -Wall -Wextra -Werror "${SAN[@]}" -o "$tmp/fmu_host" tests/c_host/fmu_host.c -ldl -lm  # POSIX (dlopen, realpath): not -std=c11
for id in planar_f45_wo4 door_h1_wo_hinge2 bricard_wo2 f45_radau f45_dop853 compliant_door_h1_wo_hinge2 \
          pendulums17_scene pgpass3_scene; do
    mkdir -p "$tmp/$id" && (cd "$tmp/$id" && unzip -q "../fmus/$id.fmu")
    $CC "${FLAGS[@]}" "${SAN[@]}" -shared -fPIC -o "$tmp/$id/binaries/linux64/$id.so" "$FMI"/fmu_*.c "$FMI"/fmi2_*.c "$CORE"/*.c -lm
    guid=$(sed -n 's/.*guid="\([^"]*\)".*/\1/p' "$tmp/$id/modelDescription.xml" | head -n 1)
    vrs=$("$PY" -c "import fmpy, sys; md = fmpy.read_model_description(sys.argv[1]); print(' '.join(f'{v.valueReference}:{v.name}' for v in md.modelVariables if v.causality == 'output' and v.type == 'Real'))" "$tmp/$id")
    # shellcheck disable=SC2086
    ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
        "$tmp/fmu_host" -q -S -w "$tmp/$id" "$id" "$guid" 0 1 0.01 1e-9 $vrs > "$tmp/$id.csv"
    echo "sanitize: C-runtime FMU $id: $(($(wc -l < "$tmp/$id.csv") - 1)) rows, FMU state restored bit for bit"
done
# The FMI 3.0 layer (fmu_*.c and fmi3_*.c over the core), sanitized, by the plain FMI 3.0 host: co-simulation
# with the FMU state through its bytes (-S), and Model Exchange (-M: the host's Euler steps, the quaternion
# event of fmu_me.c) on a friction scene and a quaternion scene.
"$PY" - "$tmp/fmus3" <<'PYEOF'
import sys
from overcon.fmu.build import build_all
code, _ = build_all(["mechanisms/planar_f45_wo4.toml", "mechanisms/examples/door_h1_wo_hinge2.toml"], sys.argv[1],
                    refs=False, validate=False, runtime="c", fmi=3, allow_nonunique=True, echo=lambda s: None)
sys.exit(code)
PYEOF
$CC -O2 -Wall -Wextra -Werror "${SAN[@]}" -o "$tmp/fmu_host3" tests/c_host/fmu_host3.c -ldl -lm
arch=$(uname -m)
for id in planar_f45_wo4 door_h1_wo_hinge2; do
    mkdir -p "$tmp/3_$id" && (cd "$tmp/3_$id" && unzip -q "../fmus3/$id.fmu")
    $CC "${FLAGS[@]}" "${SAN[@]}" -shared -fPIC -o "$tmp/3_$id/binaries/$arch-linux/$id.so" "$FMI"/fmu_*.c "$FMI"/fmi3_*.c "$CORE"/*.c -lm
    token=$(sed -n 's/.*instantiationToken="\([^"]*\)".*/\1/p' "$tmp/3_$id/modelDescription.xml" | head -n 1)
    vrs=$("$PY" -c "import fmpy, sys; md = fmpy.read_model_description(sys.argv[1]); print(' '.join(f'{v.valueReference}:{v.name}' for v in md.modelVariables if v.causality == 'output' and v.type == 'Float64' and not v.dimensions))" "$tmp/3_$id")
    # shellcheck disable=SC2086
    ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
        "$tmp/fmu_host3" -q -S -w "$tmp/3_$id" "$id" "$token" 0 1 0.01 1e-9 $vrs > "$tmp/3_$id.csv"
    # shellcheck disable=SC2086
    ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
        "$tmp/fmu_host3" -q -M -w "$tmp/3_$id" "$id" "$token" 0 0.2 0.001 1e-9 $vrs > "$tmp/3_${id}_me.csv"
    echo "sanitize: FMI 3.0 FMU $id: $(($(wc -l < "$tmp/3_$id.csv") - 1)) rows co-simulation, FMU state restored bit for bit; $(($(wc -l < "$tmp/3_${id}_me.csv") - 1)) rows Model Exchange"
done
# The fuzzing stage (docs/untrusted-input.md): tests/c_host/fuzz_fmu.c, a seeded hand-written
# mutator, against the FMI 2.0 layer built with ASan/UBSan (and float-cast-overflow: a double converted to
# an int out of range) on one FMU per integrator (dopri5, dop853, rk4, radau) and the quaternion door: first
# the regression states of tests/data/untrusted/states.json (crafted by tests/state_craft.py), then mutated
# states, model files and FMI call sequences, each bounded by a case count and by FUZZ_SECONDS of wall time
# per target and mode (default 6: about 90 s in all). Any sanitizer report, hang past a doStep's budget,
# accepted state outside its parameters' rules or refused state that changed the instance fails the stage.
FUZZ_SECONDS=${FUZZ_SECONDS:-6}
FUZZ_SAN=("${SAN[@]}" -fsanitize=float-cast-overflow)
mkdir -p "$tmp/fuzz"
"$PY" tests/c_host/fuzz_targets.py "$tmp/fuzz" > "$tmp/fuzz/targets.txt"
"$PY" tests/state_craft.py "$tmp/fuzz/targets.txt" "$tmp/fuzz/crafted" > "$tmp/fuzz/crafted.txt" # before the rebuild
$CC -O2 -Wall -Wextra -Werror "${FUZZ_SAN[@]}" -o "$tmp/fuzz_fmu" tests/c_host/fuzz_fmu.c -ldl -lm
$CC "${FLAGS[@]}" "${FUZZ_SAN[@]}" -shared -fPIC -o "$tmp/fuzz/fmi2_san.so" "$FMI"/fmu_*.c "$FMI"/fmi2_*.c "$CORE"/*.c -lm
while read -r id dir _; do  # one sanitized build of the FMI 2.0 layer: every target's binary
    cp "$tmp/fuzz/fmi2_san.so" "$dir/binaries/linux64/$id.so"
done < "$tmp/fuzz/targets.txt"
export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
while read -r id file; do
    line=$(grep "^$id " "$tmp/fuzz/targets.txt")
    read -r _ dir guid args <<< "$line"
    # shellcheck disable=SC2086
    "$tmp/fuzz_fmu" replay "$dir" "$id" "$guid" 0 1 60 $args -r "$file" > /dev/null
done < "$tmp/fuzz/crafted.txt"
echo "sanitize: $(wc -l < "$tmp/fuzz/crafted.txt") regression states (tests/data/untrusted/states.json) replayed"
while read -r id dir guid args; do
    for mode in states model calls; do
        # shellcheck disable=SC2086
        "$tmp/fuzz_fmu" $mode "$dir" "$id" "$guid" 20261127 100000 "$FUZZ_SECONDS" $args -o "$tmp/fuzz/out_${mode}_$id"
    done
done < "$tmp/fuzz/targets.txt"
unset ASAN_OPTIONS UBSAN_OPTIONS
if command -v clang >/dev/null 2>&1; then
    clang "${FLAGS[@]}" -shared -fPIC -o "$tmp/libovercore_clang.so" "$CORE"/*.c -lm
    echo "sanitize: the core compiles with clang -Wall -Wextra -Werror"
else
    echo "sanitize: clang not installed: only gcc's warnings checked"
fi
