#!/usr/bin/env python3
"""Where a render's time goes, per compiled function: ``perf record`` of the timed render alone, with Numba's JIT
code named.

    python benchmarks/perf_profile.py                  # the peer scene (../shared/peers) at 16 spp, else the demo
    python benchmarks/perf_profile.py --scene demo --spp 64 --top 40

``peer_scene.py --profile`` gives seconds per kernel; this gives the share of CPU samples per function, the
functions a kernel calls (``uniform_2d``, ``bsdf_eval``, libm's ``atan2``, Embree) apart from the kernel's own
loop.  Needs Linux ``perf`` (Debian: ``apt install linux-perf``); ``cpu-clock`` sampling works in a VM without
hardware counters.

How: a child process compiles the stages in an empty Numba cache (so that their symbols are known: about a minute
and a half), waits while ``perf record -p`` attaches, renders, and after perf has stopped writes
``/tmp/perf-PID.map`` (the address and size of every JIT symbol, which perf reads for JIT code) before it exits.
Each stage body and every function it calls (not inlined) is reported under its Python name.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _demangle(symbol: str) -> str:
    """``_ZN10lightprobe8sampling3rng10uniform_2dB3v78...`` -> ``lightprobe.sampling.rng.uniform_2d``."""
    parts, rest = [], symbol[3:]
    while rest and rest[0].isdigit():
        digits = re.match(r"\d+", rest).group()
        n = int(digits)
        parts.append(rest[len(digits) : len(digits) + n])
        rest = rest[len(digits) + n :]
    return ".".join(parts) or symbol


def child(args) -> None:
    work = Path(args.work)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    import numba

    from lightprobe.integrators.wavefront import RenderSettings, render

    if args.scene == "peer":
        from lightprobe.peer import peer_scene

        scene = peer_scene()
        warm = peer_scene(resolution=(32, 32))
    elif args.scene in ("area", "many"):
        from lightprobe.reference_scenes import build

        scene = build(args.scene, resolution=(320, 240))
        warm = build(args.scene, resolution=(32, 24))
    else:
        from lightprobe.demo import demo_scene

        scene = demo_scene()
        warm = demo_scene(resolution=(32, 20))
    render(warm, RenderSettings(spp=4))  # compile
    (work / "ready").touch()
    while not (work / "go").exists():
        time.sleep(0.05)
    result = render(scene, RenderSettings(spp=args.spp))
    (work / "done").write_text(json.dumps({"seconds": result.stats.get("seconds")}))
    while not (work / "stopped").exists():
        time.sleep(0.05)
    engine = numba.core.registry.cpu_target.target_context.codegen()._engine
    symbols = sorted(
        (address, name) for name in engine._defined_symbols if (address := engine._ee.get_function_address(name)) != 0
    )
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as out:
        for (address, name), (following, _) in zip(symbols, [*symbols[1:], (symbols[-1][0] + 4096, "")], strict=True):
            out.write(f"{address:x} {min(following - address, 1 << 20):x} {name}\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--scene", choices=["peer", "demo", "area", "many"], help="default: peer if ../shared/peers is found"
    )
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--top", type=int, default=30, help="functions to list")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--work", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return
    if shutil.which("perf") is None:
        sys.exit("perf_profile.py: needs Linux perf on PATH (Debian: apt install linux-perf)")
    if args.scene is None:
        from lightprobe.peer import find_peers

        args.scene = "peer" if find_peers() is not None else "demo"
    with tempfile.TemporaryDirectory(prefix="lightprobe-perf-") as work:
        env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(work) / "numba"))
        command = [sys.executable, __file__, "--child", "--work", work, "--scene", args.scene, "--spp", str(args.spp)]
        print(f"compiling in a fresh cache, then rendering the {args.scene} scene at {args.spp} spp ...", flush=True)
        proc = subprocess.Popen(command, env=env)
        while not Path(work, "ready").exists():
            if proc.poll() is not None:
                sys.exit(f"perf_profile.py: the render process failed (exit {proc.returncode})")
            time.sleep(0.1)
        data = str(Path(work, "perf.data"))
        perf = subprocess.Popen(
            ["perf", "record", "-e", "cpu-clock", "-F", "2000", "-p", str(proc.pid), "-o", data],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        time.sleep(1.0)  # perf attaches
        Path(work, "go").touch()
        while not Path(work, "done").exists():
            if proc.poll() is not None:
                perf.send_signal(signal.SIGINT)
                sys.exit(f"perf_profile.py: the render process failed (exit {proc.returncode})")
            time.sleep(0.05)
        perf.send_signal(signal.SIGINT)
        _, err = perf.communicate()
        Path(work, "stopped").touch()
        proc.wait()
        if perf.returncode not in (0, -signal.SIGINT) or not Path(data).exists():
            sys.exit(f"perf_profile.py: perf record failed: {err.decode().strip().splitlines()[-1:]}")
        seconds = json.loads(Path(work, "done").read_text())["seconds"]
        script = subprocess.run(
            ["perf", "script", "-i", data, "-F", "ip,sym,dso"], capture_output=True, text=True, check=True
        ).stdout
        os.unlink(f"/tmp/perf-{proc.pid}.map")
    counts = collections.Counter()
    for line in script.splitlines():
        line = line.strip()
        if not line:
            continue
        _, _, rest = line.partition(" ")  # "ip symbol (dso)"
        symbol, _, dso = rest.strip().rpartition(" ")
        symbol = symbol.strip() or "[unknown]"
        if symbol.startswith("_ZN"):
            key = _demangle(symbol)
        elif "embree" in dso:
            key = "Embree (libembree4, called from the kernels)" if symbol == "[unknown]" else f"Embree {symbol}"
        else:
            key = f"{symbol} ({Path(dso.strip('()')).name})"
        counts[key] += 1
    total = sum(counts.values())
    print(f"render: {seconds:.2f} s, {total} samples (cpu-clock, both threads)")
    print(json.dumps({"scene": args.scene, "spp": args.spp, "seconds": seconds, "samples": total}))
    for key, n in counts.most_common(args.top):
        print(f"{100 * n / total:6.2f} %  {key}")


if __name__ == "__main__":
    main()
