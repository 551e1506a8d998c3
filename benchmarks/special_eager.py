"""The special functions called without ``jit``: one compiled program against op by op, and scipy.special.

A user who calls ``frbjax.special.ellippiinc(n, phi, m)`` eagerly on a small array gets one compiled
program per argument types (``frbjax.special._compiled.one_program``); before, the function's
operations were dispatched one by one at every call (its ``__wrapped__``, timed here as "op by op").
For each function, in a fresh process per mode (so that nothing is compiled before): the first
call's time (compile included) and the median time of 20 later calls, on 21 points; scipy.special's
eager call on the same points is the peer.  Prints the ratios and writes special_eager.json into
``--output-dir`` (benchmarks/results by default).

    taskset -c 0 python benchmarks/special_eager.py [--quick] [--output-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys


FUNCTIONS = ("ellipk", "ellipkinc", "ellippiinc", "ellipj", "elliprj")
MODES = ("one program", "op by op", "scipy")
RESULTS = pathlib.Path(__file__).resolve().parent / "results" / "special_eager.json"

CHILD = r"""
import json, sys, time
import numpy as np
name, mode = sys.argv[1], sys.argv[2]
rng = np.random.default_rng(0)
arguments = {
    "ellipk": (rng.uniform(0, 1, 21),),
    "ellipkinc": (rng.uniform(-3, 3, 21), rng.uniform(0, 1, 21)),
    "ellippiinc": (rng.uniform(-1, 0.9, 21), rng.uniform(-1.5, 1.5, 21), rng.uniform(0, 1, 21)),
    "ellipj": (rng.uniform(-5, 5, 21), rng.uniform(0, 1, 21)),
    "elliprj": tuple(rng.uniform(0.1, 2, 21) for _ in range(4)),
}[name]
if mode == "scipy":
    import scipy.special
    function = getattr(scipy.special, name, None)
    if name == "ellippiinc":  # scipy.special has no Pi(n; phi|m): Carlson's form, |phi| <= pi/2 (DLMF 19.25.14)
        def function(n, phi, m):
            s, c = np.sin(phi), np.cos(phi)
            d = 1 - m * s * s
            third = scipy.special.elliprj(c * c, d, 1, 1 - n * s * s)
            return s * scipy.special.elliprf(c * c, d, 1) + n / 3 * s**3 * third
    ready = lambda out: out
else:
    import jax
    jax.config.update("jax_enable_x64", True)
    import frbjax.special as special
    public = getattr(special, name)
    function = public if mode == "one program" else public.__wrapped__
    ready = jax.block_until_ready
start = time.perf_counter()
ready(function(*arguments))
first = time.perf_counter() - start
times = []
for _ in range(20):
    start = time.perf_counter()
    ready(function(*arguments))
    times.append(time.perf_counter() - start)
print(json.dumps({"first_s": first, "call_s": float(np.median(times))}))
"""


def measure(name, mode):
    out = subprocess.run(
        [sys.executable, "-c", CHILD, name, mode], capture_output=True, text=True, check=True, timeout=600
    ).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="ellipk only, one program and scipy (a smoke run)")
    parser.add_argument("--output-dir", type=pathlib.Path, default=RESULTS.parent)
    args = parser.parse_args()
    functions = ("ellipk",) if args.quick else FUNCTIONS
    modes = ("one program", "scipy") if args.quick else MODES
    results = {"points": 21, "functions": {}}
    for name in functions:
        row = {mode: measure(name, mode) for mode in modes}
        results["functions"][name] = row
        line = ", ".join(
            f"{mode}: first {row[mode]['first_s']:.3f} s, {1e6 * row[mode]['call_s']:.1f} us a call" for mode in modes
        )
        print(f"{name}: {line}", flush=True)
        ratios = [f"one program / scipy per call {row['one program']['call_s'] / row['scipy']['call_s']:.1f}"]
        if "op by op" in row:
            ratios.insert(
                0, f"op by op / one program per call {row['op by op']['call_s'] / row['one program']['call_s']:.0f}"
            )
            ratios.insert(1, f"first call {row['op by op']['first_s'] / row['one program']['first_s']:.2f}")
        print(f"  {'; '.join(ratios)}", flush=True)
    output = args.output_dir / RESULTS.name
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
