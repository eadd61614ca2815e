"""Seconds numba takes to compile each stage's kernels on a fresh installation, and to load them after.

Two fresh interpreters, each with ``NUMBA_CACHE_DIR`` a new empty folder
and one numba thread, compile what `cutkit demo`'s two processes compile
(``cutkit.demo.warmup``):

* the build side: a marching isovolume of a small label map, then a
  decimation of the run side's warm-up slab;
* the run side: the warm-up slab's short cut without outputs
  (``cutkit.simulate.warmup.warm_up(outputs=False, extras=False)``), then
  with its outputs, then ``warm_up_extras`` (each after the one before, so
  each figure is what it adds).

Both run again with their caches filled (``warm_s``: the kernels load).  The
inputs are tiny, so nearly all of ``cold_s`` is compiling.

    python benchmarks/compile.py [--json]
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile

_BUILD = """
import json, time
import numpy as np
t = [time.perf_counter()]
from cutkit.decimate import decimate
from cutkit.isovolume import isovolume
from cutkit.simulate.warmup import warm_up_model
from cutkit.volumes import Volume
t.append(time.perf_counter())
labels = np.zeros((9, 8, 7), np.int32)
labels[2:7, 2:6, 2:5] = 1
labels[3:5, 3:5, 3:4] = 2
isovolume(Volume(labels))
t.append(time.perf_counter())
decimate(warm_up_model(fixed_ends=False), ratio=0.7)
t.append(time.perf_counter())
print(json.dumps({"import": t[1] - t[0], "isovolume": t[2] - t[1], "decimate": t[3] - t[2]}))
"""

_RUN = """
import json, time
t = [time.perf_counter()]
from cutkit.simulate import warmup
t.append(time.perf_counter())
warmup.warm_up(outputs=False, extras=False)
t.append(time.perf_counter())
warmup.warm_up(outputs=True, extras=False)
t.append(time.perf_counter())
warmup.warm_up_extras()
t.append(time.perf_counter())
print(json.dumps({"import": t[1] - t[0], "short_cut": t[2] - t[1], "outputs": t[3] - t[2], "extras": t[4] - t[3]}))
"""


def timed(script: str, cache: str) -> dict:
    """Run ``script`` in a fresh interpreter on numba cache folder ``cache``; its JSON line."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, NUMBA_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", script], env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    result = {"machine": platform.machine(), "python": platform.python_version(),
              "load_1min": os.getloadavg()[0]}
    for side, script in (("build", _BUILD), ("run", _RUN)):
        with tempfile.TemporaryDirectory() as cache:
            result[side] = {"cold_s": timed(script, cache), "warm_s": timed(script, cache)}
    if args.json:
        print(json.dumps(result))
        return
    for side in ("build", "run"):
        for stage, s in result[side]["cold_s"].items():
            print(f"{side + '.' + stage:20s} cold {s:7.1f} s   warm {result[side]['warm_s'][stage]:6.2f} s")


if __name__ == "__main__":
    main()
