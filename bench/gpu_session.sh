#!/usr/bin/env bash
# One command that checks a GPU machine: the physics tests on CUDA, then bench/gpu.py, inside a
# fixed time budget (CALL_BUDGET seconds), results under OUT as they come.  Warp must be
# importable (installed, or on PYTHONPATH):
#
#   OUT=/tmp/gpu_session bash bench/gpu_session.sh
#
# 0. bench/gpu.py --compile-only: every kernel module compiled for the device (NVRTC) and the CPU
#    on parallel threads, into the kernel cache the later steps load from (tests launching
#    modules one by one would otherwise spend their budget compiling).  CUDA_CACHE=file.tar.xz
#    (bench/cuda_cache.py, built on any machine from the same sources) is unpacked into the
#    cache first, so NVRTC is skipped (141 s on the H200 machine).
# 1. Every test that takes ``device`` (tests/conftest.py), run with --cuda and only its cuda:0
#    instances (the CPU ones ran in CI), the CUDA contract's files first (graph capture, pair
#    overflow, determinism, ...), on 8 workers where pytest-xdist is installed; the run
#    gets TEST_BUDGET seconds and is then interrupted (SIGINT), so pytest still writes its
#    summary and junit XML into $OUT.
# 2. bench/gpu.py --device cuda:0 with what is left of CALL_BUDGET (it skips a part that would
#    not fit, caps every stepping loop, and writes gpu.json / gpu.csv / gpu.png after each part).
#
# At most 7 files land in OUT (environment.txt, cuda_tests.txt/.xml, gpu_log.txt, gpu.json/.csv/.png),
# so that a remote runner that brings back a few files gets all of them.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-${1:-/tmp/gpu_session}}
CALL_BUDGET=${CALL_BUDGET:-520}
TEST_BUDGET=${TEST_BUDGET:-140}
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
# the CUDA contract first (capture, overflow, determinism, mid-step passes, scans): a run cut
# off by its budget has then checked what only a GPU can show
FIRST = ["test_graph_capture.py", "test_pair_overflow.py", "test_determinism.py", "test_late_contacts.py",
         "test_prefix_sum.py"]
paths = sorted(pathlib.Path("tests").glob("test_*.py"), key=lambda p: (p.name not in FIRST,
                                                                         FIRST.index(p.name) if p.name in FIRST else 0,
                                                                         p.name))
for path in paths:
    tree = ast.parse(path.read_text())
    if any(isinstance(node, ast.FunctionDef) and node.name.startswith("test")
           and any(a.arg == "device" for a in node.args.args) for node in ast.walk(tree)):
        print(path)
PYEOF
)
files=$(echo $files)
if [ -n "${CUDA_CACHE:-}" ] && [ -f "$CUDA_CACHE" ]; then
    # cubins built ahead of time (bench/cuda_cache.py) for these very sources: no NVRTC here
    # the last line only: Warp may print its banner (with the same path) before it
    cache_dir=$(python3 -c "import warp as wp; wp.config.log_level = wp.LOG_WARNING; wp.init(); \
print(wp.config.kernel_cache_dir)" 2>/dev/null | tail -n 1)
    case "$cache_dir" in /*) ;; *) echo "no kernel cache folder found: $CUDA_CACHE not unpacked"; cache_dir="" ;; esac
    [ -n "$cache_dir" ] && mkdir -p "$cache_dir" && tar -xJf "$CUDA_CACHE" -C "$cache_dir" \
        && echo "[$(elapsed) s] unpacked $CUDA_CACHE into $cache_dir" | tee -a "$OUT/environment.txt"
fi
timeout 300 python3 bench/gpu.py --compile-only --device "$DEVICE" --out "$OUT" 2>&1 | tee -a "$OUT/environment.txt"
# the tests get at most half of what is left after the compile (a cold kernel cache costs minutes)
half=$(( (CALL_BUDGET - $(elapsed)) / 2 ))
[ "$half" -lt "$TEST_BUDGET" ] && TEST_BUDGET=$half
workers=""
python3 -c "import xdist" 2>/dev/null && workers="-n 8"
echo "[$(elapsed) s] tests on $DEVICE ${workers:-(one process)}: $files"
timeout -s INT -k 20 "$TEST_BUDGET" python3 -m pytest -q -p no:cacheprovider $workers --cuda -k "cuda" -rfEs \
    --durations=10 --junitxml "$OUT/cuda_tests.xml" $files 2>&1 | tee "$OUT/cuda_tests.txt"
echo "[$(elapsed) s] tests exit status ${PIPESTATUS[0]} (2 or 124: cut off at $TEST_BUDGET s)"

left=$(( CALL_BUDGET - $(elapsed) ))
if [ "$left" -lt 60 ]; then
    echo "[$(elapsed) s] $left s left of $CALL_BUDGET: bench/gpu.py not started"
    exit 0
fi
echo "[$(elapsed) s] bench/gpu.py with a budget of $left s"
timeout -k 10 $(( left + 30 )) python3 bench/gpu.py --out "$OUT" --device "$DEVICE" --budget "$left" $GPU_ARGS \
    2>&1 | tee "$OUT/gpu_log.txt"
echo "[$(elapsed) s] done"
