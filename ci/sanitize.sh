#!/usr/bin/env bash
# The C core under AddressSanitizer and UndefinedBehaviorSanitizer (and LeakSanitizer, part of
# ASan on Linux): tests/c_core/make_cases.py writes packed models and the results the installed
# core gives (the paper's planar and spatial mechanisms, the quaternion examples with spatial revolute,
# prismatic, cylindrical and spherical joints, a chain of every spatial joint type, damped-Newton states and every failure
# status), then tests/c_core/driver.c, compiled with the core's sources and the sanitizers, runs
# every case 20 times in two workspaces and requires the same bits, statuses and messages. Any
# out-of-bounds access, leak or undefined behaviour stops it with the sanitizer's report.
# Also compiles the core with clang -Werror when clang is installed. About 10 s.
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
if command -v clang >/dev/null 2>&1; then
    clang "${FLAGS[@]}" -shared -fPIC -o "$tmp/libovercore_clang.so" "$CORE"/*.c -lm
    echo "sanitize: the core compiles with clang -Wall -Wextra -Werror"
else
    echo "sanitize: clang not installed: only gcc's warnings checked"
fi
