"""The fused hash-encoding kernels against the tensor path, alone: relative differences of values and table
gradients, and forward + backward time, on random points: the ``triton`` backend on CUDA, ``cpp`` on the CPU.

    python benchmarks/hash_kernel.py                      # the paper's encoder: 16 levels 16 -> 512, 2^19 entries
    python benchmarks/hash_kernel.py --points 400000 --repeats 20

Writes ``hash_kernel.json`` under ``--out``.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from nerif.encoders.hash import HashGrid
from nerif.export import write_json


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=400_000)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--levels", type=int, default=16)
    ap.add_argument("--finest", type=int, default=512)
    ap.add_argument("--log2-table", type=int, default=19)
    ap.add_argument("--out", default="benchmarks/results/hash_kernel")
    args = ap.parse_args()
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    torch.manual_seed(0)
    rows = {}
    for interp in ("linear", "smoothstep"):
        enc = HashGrid(n_levels=args.levels, log2_table_size=args.log2_table, max_resolution=args.finest,
                       init_scale=1.0, interpolation=interp).to(device)
        x = torch.rand(args.points, 3, device=device) * 2.2 - 1.1
        g = torch.randn(args.points, enc.out_dim, device=device)
        res = {}
        fused = "triton" if device.type == "cuda" else "cpp"
        for kernel in ("torch", fused):
            enc.kernel = kernel
            y = enc(x)
            (gt,) = torch.autograd.grad(y, enc.table, g)
            res[kernel] = (y.detach(), gt)
            for _ in range(3):
                enc(x).backward(g)
            sync()
            t = time.perf_counter()
            for _ in range(args.repeats):
                enc(x).backward(g)
            sync()
            res[kernel + "_ms"] = 1e3 * (time.perf_counter() - t) / args.repeats
        (y_ref, g_ref), (y, gf) = res["torch"], res[fused]
        rows[interp] = {"value_rel_diff": float((y - y_ref).norm() / y_ref.norm()),
                        "grad_rel_diff": float((gf - g_ref).norm() / g_ref.norm()),
                        "torch_ms": res["torch_ms"], "fused_ms": res[fused + "_ms"], "backend": fused}
        r = rows[interp]
        print(f"{interp}: values {r['value_rel_diff']:.1e}, table gradients {r['grad_rel_diff']:.1e} (relative); "
              f"forward + backward of {args.points} points x {args.levels} levels: tensor path {r['torch_ms']:.2f} ms, "
              f"fused ({fused}) {r['fused_ms']:.2f} ms", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json({"device": str(device), "args": vars(args), "rows": rows}, out / "hash_kernel.json")


if __name__ == "__main__":
    main()
