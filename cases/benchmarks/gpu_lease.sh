#!/bin/bash
# One GPU lease's checks and figures, in two parts that each fit a 10-minute command.
#
#   bash cases/benchmarks/gpu_lease.sh check   # device, versions; GPU == CPU on the comparison
#                                               # scene (120 steps); the intact-step figure
#   bash cases/benchmarks/gpu_lease.sh scene MESH.npz SCENE.toml SECONDS
#                                               # the fragmented figure; the paper-scale four
#                                               # slopes on the GPU for SECONDS of wall time
#
# The node needs numpy, scipy, numba and numba-cuda (docs/gpu.md; pytest too, for the check's
# comparison, which uses the test's own tolerances): the scene is meshed
# elsewhere (`fdem run four-slopes --size 0.18 --max-steps 0` writes the .npz, `--write-scene`
# the .toml). Logs and the figures' JSON go to $OUT (default runs/gpu_lease); each stage has its
# own wall-clock limit and is interrupted with SIGINT, so a stage that runs long still leaves its
# log and its checkpoint, and the next stage runs.
set -u
export PYTHONUNBUFFERED=1 PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
OUT=${OUT:-runs/gpu_lease}
mkdir -p "$OUT"
py=${PYTHON:-python3}

stage() {  # stage NAME SECONDS COMMAND...: run it under a limit, log to $OUT/NAME.log
    local name=$1 secs=$2; shift 2
    local t0=$SECONDS
    echo "== $name (limit ${secs} s)"
    timeout -s INT -k 60 "$secs" "$@" >"$OUT/$name.log" 2>&1
    local rc=$?
    echo "== $name: exit $rc after $((SECONDS - t0)) s"
    tail -n 12 "$OUT/$name.log" | tr '\r' '\n' | tail -n 12
}

case ${1:-} in
check)
    {
        nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv
        $py -c "import numpy, scipy, numba, numba_cuda; from numba import cuda; \
print('numpy', numpy.__version__, 'scipy', scipy.__version__, 'numba', numba.__version__, \
'numba-cuda', numba_cuda.__version__, 'gpu', cuda.get_current_device().name)"
        nproc
    } >"$OUT/info.log" 2>&1
    cat "$OUT/info.log"
    # the comparison scene of tests/unit/test_cuda_backend.py from the start, compiled kernels
    # and hardware atomics against the CPU, checked with the test's own tolerances
    stage compare 200 bash -c "cd tests/unit && $py cuda_scene.py cpu /tmp/ref.npz --steps 120 && \
$py cuda_scene.py cuda /tmp/gpu.npz --steps 120 && $py -c \"
import numpy as np, test_cuda_backend as t
a, b = dict(np.load('/tmp/gpu.npz')), dict(np.load('/tmp/ref.npz'))
print('broken', int(a['broken'].sum()), int(b['broken'].sum()), 'touching', int(a['touching'].sum()),
      'max |dx| m', float(np.abs(a['x'] - b['x']).max()), 'max |dv| m/s', float(np.abs(a['v'] - b['v']).max()))
t.assert_same_run(a, b)
print('GPU equals CPU over 120 steps within the test tolerances')\""
    stage intact 150 $py cases/benchmarks/bench_gpu.py intact --triangles 1000000 --seconds 1 --repeats 3
    cp docs/benchmarks/gpu_intact.json "$OUT/" 2>/dev/null
    # bench_gpu.py writes docs/benchmarks/gpu_intact.json: the batched figure is kept in $OUT above
    stage intact_single 60 $py cases/benchmarks/bench_gpu.py intact --triangles 1000000 --seconds 1 --repeats 2 --max-batch 1
    cp docs/benchmarks/gpu_intact.json "$OUT/gpu_intact_single.json" 2>/dev/null
    ;;
scene)
    mesh=$2 scene=$3 secs=$4
    stage fragmented 120 $py cases/benchmarks/bench_gpu.py fragmented --triangles 250000 --seconds 1 --repeats 3
    cp docs/benchmarks/gpu_fragmented.json "$OUT/" 2>/dev/null
    rm -rf /tmp/four_slopes
    stage four_slopes "$secs" $py -m fdem run "$scene" --mesh "$mesh" --backend cuda --out /tmp/four_slopes \
        --yes --no-pictures
    for f in summary.json history.csv; do cp /tmp/four_slopes/$f "$OUT/" 2>/dev/null; done
    ls -la /tmp/four_slopes | head -30
    ;;
*)
    echo "usage: $0 check | scene MESH.npz SCENE.toml SECONDS" >&2
    exit 2
    ;;
esac
