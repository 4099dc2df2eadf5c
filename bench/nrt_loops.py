"""Where numba left reference counting in a kernel's loops: the loop blocks of its optimised IR.

    python -m bench.nrt_loops [--kernel service.core.methods.quad_kernel:quad_search]
        [--camera seed000] [--random 30]

numba takes and gives back a reference count (``NRT_incref`` / ``NRT_decref``, an atomic
operation and a call each) for the arrays a function receives or aliases, and its pruning pass
removes the pairs it can prove redundant. Where a pair stays inside a loop it is paid on every
iteration: an inlined helper's array arguments, a row view, a call into numba's sort. This
script solves a few frames on the default database so that the kernel is compiled for the types
the product passes, compiles a fresh copy of it (a cached kernel's IR cannot be read back), and
lists the blocks of its optimised LLVM IR that lie on a cycle of its control flow (Tarjan's
strongly connected components) and call the reference counting, with the values they count.
``--random N`` solves N random-point frames (the refusal path) instead of simulated stars.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import importlib  # noqa: E402
import re  # noqa: E402
import sys  # noqa: E402
from collections.abc import Sequence  # noqa: E402

_LABEL = re.compile(r"^([A-Za-z0-9_.$\"-]+):")
_TARGET = re.compile(r"label %([A-Za-z0-9_.$\"-]+)")
_NRT = re.compile(r"call void @NRT_(incref|decref)\(ptr (?:nonnull )?(%[^) ,]+)")


def function_blocks(ir: str, name_part: str) -> dict[str, list[str]]:
    """The basic blocks (label -> lines, in order) of the first function defined in ``ir`` whose
    name holds ``name_part`` (numba's CPython wrapper left out)."""
    for m in re.finditer(r"\ndefine [^\n]*\{\n", ir):
        head = m.group(0)
        if name_part in head and "cpython" not in head.split("(")[0]:
            body = ir[m.end():ir.index("\n}\n", m.end())]
            break
    else:
        raise ValueError(f"no function named like {name_part!r} in the IR")
    blocks: dict[str, list[str]] = {"entry": []}
    cur = "entry"
    for line in body.split("\n"):
        lm = _LABEL.match(line)
        if lm:
            cur = lm.group(1).strip('"')
            blocks[cur] = []
        else:
            blocks[cur].append(line)
    return blocks


def loop_blocks(blocks: dict[str, list[str]]) -> set[str]:
    """The blocks that lie on a cycle of the control flow (an SCC of more than one block, or a
    block that branches to itself), found iteratively (Tarjan)."""
    succ = {b: [t.strip('"') for t in _TARGET.findall("\n".join(lines))] for b, lines in blocks.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    in_loop: set[str] = set()
    counter = 0
    for root in blocks:
        if root in index:
            continue
        work = [(root, iter(succ[root]))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in blocks:
                    continue
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(succ[w])))
                    advanced = True
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1 or v in succ[v]:
                    in_loop.update(comp)
    return in_loop


def refcounts_in_loops(ir: str, name_part: str) -> list[tuple[str, list[tuple[str, str]]]]:
    """``(block, [(incref|decref, value), ...])`` for each loop block of the function that
    counts references, in the IR's order."""
    blocks = function_blocks(ir, name_part)
    loops = loop_blocks(blocks)
    out = []
    for b, lines in blocks.items():
        calls = [m.groups() for line in lines for m in [_NRT.search(line)] if m]
        if calls and b in loops:
            out.append((b, calls))
    return out


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kernel", default="service.core.methods.quad_kernel:quad_search")
    ap.add_argument("--camera", default="seed000")
    ap.add_argument("--random", type=int, default=30)
    args = ap.parse_args(argv)
    import numpy as np
    from numba import njit

    from service.core.navdb import ensure_default_database, open_database
    from service.core.pipeline import SolveOptions, solve
    from service.core.presets import PRESETS
    from service.core.sim import SimConfig, random_points, simulate_frames

    module, name = args.kernel.split(":")
    kernel = getattr(importlib.import_module(module), name)
    db = open_database(ensure_default_database())
    p = PRESETS[args.camera]
    if args.random:
        rng = np.random.default_rng(0)
        frames = [random_points(p.camera, int(n), rng) for n in rng.integers(5, 40, args.random)]
    else:
        frames = [f.centroids for f in simulate_frames(p.camera, 30, SimConfig(mag_limit=p.mag_limit), rng=0)]
    for c in frames:
        solve(c, p.camera, db, options=SolveOptions(centroid_sigma_px=1.0))
    if not kernel.signatures:
        raise SystemExit(f"{args.kernel} did not run on these frames")
    fresh = njit(nogil=True)(kernel.py_func)
    sig = kernel.signatures[0]
    fresh.compile(sig)
    ir = fresh.inspect_llvm(sig)
    found = refcounts_in_loops(ir, name)
    total = sum(1 for lines in function_blocks(ir, name).values() for line in lines if _NRT.search(line))
    for block, calls in found:
        print(f"{block[:40]}: {len(calls)} ({', '.join(f'{k} {v}' for k, v in calls[:6])}{', ...' if len(calls) > 6 else ''})")
    print(f"{sum(len(c) for _, c in found)} reference-count calls in loop blocks, of {total} in the function")


if __name__ == "__main__":
    sys.exit(main())
