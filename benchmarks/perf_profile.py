#!/usr/bin/env python3
"""Where a render's time goes, per compiled function: ``perf record`` of the timed render alone, with Numba's JIT
code named.

    python benchmarks/perf_profile.py                  # the peer scene (../shared/peers) at 16 spp, else the demo
    python benchmarks/perf_profile.py --scene demo --spp 64 --top 40
    python benchmarks/perf_profile.py --scene city --equal-counts --hot light_samples setup   # any suite scene

``--equal-counts`` renders with one light and one BSDF sample a camera sample (``benchmarks/equal_counts.py``'s
settings, the BVH selector); ``--hot NAME ...`` also prints, for each compiled function whose name contains NAME,
its hottest 128-byte stretches of machine code with each instruction's samples (the code is copied from the
process and disassembled with ``objdump``): where a stage waits, to the instruction (decision 132).

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
import ctypes
import json
import os
import pickle
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


#: benchmarks/equal_counts.py's settings: one light sample and one BSDF sample a camera sample
EQUAL_COUNTS = dict(n_bsdf=1, lights_per_sample=1, adaptive=False, outline_control_variate=False, light_sampler="bvh")


def child(args) -> None:
    work = Path(args.work)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    import numba

    from lightprobe.integrators.wavefront import RenderSettings, render

    if args.scene == "peer":
        from lightprobe.peer import peer_scene

        scene = peer_scene()
        warm = peer_scene(resolution=(32, 32))
    elif args.scene != "demo":
        from lightprobe.reference_scenes import build

        scene = build(args.scene, resolution=(320, 240))
        warm = build(args.scene, resolution=(32, 24))
    else:
        from lightprobe.demo import demo_scene

        scene = demo_scene()
        warm = demo_scene(resolution=(32, 20))
    options = EQUAL_COUNTS if args.equal_counts else {}
    render(warm, RenderSettings(spp=4, **options))  # compile
    (work / "ready").touch()
    while not (work / "go").exists():
        time.sleep(0.05)
    result = render(scene, RenderSettings(spp=args.spp, **options))
    (work / "done").write_text(json.dumps({"seconds": result.stats.get("seconds")}))
    while not (work / "stopped").exists():
        time.sleep(0.05)
    engine = numba.core.registry.cpu_target.target_context.codegen()._engine
    symbols = sorted(
        (address, name) for name in engine._defined_symbols if (address := engine._ee.get_function_address(name)) != 0
    )
    code = {}
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as out:
        for (address, name), (following, _) in zip(symbols, [*symbols[1:], (symbols[-1][0] + 4096, "")], strict=True):
            size = min(following - address, 1 << 20)
            out.write(f"{address:x} {size:x} {name}\n")
            if name.startswith("_ZN") and any(hot in _demangle(name) for hot in args.hot or ()):
                code[name] = (address, ctypes.string_at(address, size))  # this process's own machine code
    (work / "code.pickle").write_bytes(pickle.dumps(code))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    from lightprobe.reference_scenes import NAMES, SUITE

    parser.add_argument(
        "--scene",
        choices=sorted({"peer", "demo", *NAMES, *SUITE}),
        help="default: peer if ../shared/peers is found",
    )
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--top", type=int, default=30, help="functions to list")
    parser.add_argument("--equal-counts", action="store_true", help="one light and one BSDF sample a camera sample")
    parser.add_argument("--hot", nargs="*", metavar="NAME", help="functions whose hottest machine code to print")
    parser.add_argument("--regions", type=int, default=6, help="128-byte stretches printed per --hot function")
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
        command += ["--equal-counts"] if args.equal_counts else []
        command += ["--hot", *args.hot] if args.hot else []
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
        code = pickle.loads(Path(work, "code.pickle").read_bytes()) if args.hot else {}
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
    for name, (address, blob) in code.items():
        _print_hot(name, address, blob, script, args.regions)


def _print_hot(name: str, address: int, blob: bytes, script: str, regions: int) -> None:
    """The function's hottest 128-byte stretches, each instruction with its samples (a sample usually lands on
    the instruction after the one it waits for: a square root's or a division's latency shows on its successor)."""
    ips = collections.Counter()
    for line in script.splitlines():
        field = line.split()
        try:
            ip = int(field[0], 16) if field else -1
        except ValueError:
            continue
        if address <= ip < address + len(blob):
            ips[ip - address] += 1
    total = sum(ips.values())
    if total == 0:
        return
    with tempfile.NamedTemporaryFile(suffix=".bin") as f:
        f.write(blob)
        f.flush()
        listing = subprocess.run(
            ["objdump", "-D", "-b", "binary", "-mi386:x86-64", f.name], capture_output=True, text=True
        ).stdout
    instructions = []
    for line in listing.splitlines():
        found = re.match(r"\s*([0-9a-f]+):\s+(?:[0-9a-f]{2} )+\s*(.*)", line)
        if found and found.group(2).strip():
            instructions.append((int(found.group(1), 16), found.group(2).strip()))
    stretches = collections.Counter()
    for offset, n in ips.items():
        stretches[offset // 128] += n
    print(f"\n{_demangle(name)}: {total} samples, {len(blob)} bytes of code")
    for stretch, n in stretches.most_common(regions):
        print(f"  +{stretch * 128:#x}: {n} samples ({100 * n / total:.1f} %)")
        for offset, text in instructions:
            if stretch * 128 <= offset < (stretch + 1) * 128 and (
                ips[offset] or "call" in text or "div" in text or "sqrt" in text
            ):
                print(f"    {offset:#7x} {ips[offset]:5d}  {text}")


if __name__ == "__main__":
    main()
