#!/usr/bin/env bash
# The one prepared command for a lent GPU: the physics tests on CUDA, then bench/gpu.py.
#
# A lent machine has 15 minutes in all (its start-up and the transfers count), one command at a
# time, at most 10 minutes a command, and no Warp: ../shared/hooks/device/prepare.sh splits the
# Warp wheel into three parts that three back-to-back calls carry.  This script is the third
# call's work, after the wheel is installed:
#
#   bash .device/p3/install.sh && export PYTHONPATH=/tmp/site:$PWD && bash bench/gpu_session.sh
#
# 1. Every test that takes ``device`` (tests/conftest.py), run with --cuda and only its cuda:0
#    instances (the CPU ones ran in CI); the test run gets TEST_BUDGET seconds, its log and
#    junit XML land in $OUT first, so a cut-off run still reports what it ran.  The first test to
#    launch a module compiles it with NVRTC, which warms the kernel cache for step 2.
# 2. bench/gpu.py --device cuda:0 with what is left of CALL_BUDGET (it skips a part that would
#    not fit, and writes gpu.json / gpu.csv / gpu.png after each part).
#
# CALL_BUDGET leaves a minute of the 600 s a command may run for the transfers back.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-${1:-/tmp/gpu_session}}
CALL_BUDGET=${CALL_BUDGET:-540}
TEST_BUDGET=${TEST_BUDGET:-150}
DEVICE=${DEVICE:-cuda:0}
GPU_ARGS=${GPU_ARGS:-}  # e.g. --quick, for a dry run on the CPU: DEVICE=cpu GPU_ARGS=--quick
export PYTHONUNBUFFERED=1
mkdir -p "$OUT"
start=$(date +%s)
elapsed() { echo $(( $(date +%s) - start )); }

python3 - <<'EOF' 2>&1 | tee "$OUT/environment.txt"
import platform, warp as wp
wp.init()
print("python", platform.python_version(), "warp", wp.config.version, "cuda", wp.is_cuda_available())
for d in wp.get_devices():
    print(" ", d.alias, d.name)
EOF

# the test files with device-parametrised tests (their cuda:0 instances are what runs here)
files=$(python3 - <<'PYEOF'
import ast, pathlib
for path in sorted(pathlib.Path("tests").glob("test_*.py")):
    tree = ast.parse(path.read_text())
    if any(isinstance(node, ast.FunctionDef) and node.name.startswith("test")
           and any(a.arg == "device" for a in node.args.args) for node in ast.walk(tree)):
        print(path)
PYEOF
)
files=$(echo $files)
echo "[$(elapsed) s] tests on $DEVICE: $files"
timeout "$TEST_BUDGET" python3 -m pytest -q -p no:cacheprovider --cuda -k "cuda" -rfEs \
    --junitxml "$OUT/cuda_tests.xml" $files 2>&1 | tee "$OUT/cuda_tests.txt"
echo "[$(elapsed) s] tests exit status ${PIPESTATUS[0]} (124: cut off at $TEST_BUDGET s)"

left=$(( CALL_BUDGET - $(elapsed) ))
if [ "$left" -lt 60 ]; then
    echo "[$(elapsed) s] $left s left of $CALL_BUDGET: bench/gpu.py not started"
    exit 0
fi
echo "[$(elapsed) s] bench/gpu.py with a budget of $left s"
python3 bench/gpu.py --out "$OUT" --device "$DEVICE" --budget "$left" $GPU_ARGS 2>&1 | tee "$OUT/gpu_log.txt"
echo "[$(elapsed) s] done"
