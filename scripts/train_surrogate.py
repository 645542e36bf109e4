"""Fit the reduced-order wing (:class:`kite_env.surrogate.model.SurrogateWing`) to samples of the full wing.

    python scripts/train_surrogate.py --samples runs/surrogate/samples.npz --out runs/surrogate/rhino16.npz
           [--hidden 128,128] [--epochs 400] [--batch 0] [--lr 2e-3] [--holdout 5] [--seed 0]

Episodes (sample groups) are split, not rows: every ``--holdout``-th episode is held out for validation, so that
the errors are those on flights the model has not seen. Loss: mean squared error of the normalised outputs (Adam,
full batch or shuffled mini-batches of ``--batch`` rows, learning rate halved when the held-out loss stalls for
``--patience`` epochs); the weights of the epoch with the lowest held-out loss are kept.
Prints per-output held-out RMS errors and the bridle-force RMS error relative to the mean traction, and writes
them with the provenance of the samples into the weights file.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--samples", required=True)
    p.add_argument("--out", required=True, help="weights file (.npz)")
    p.add_argument("--hidden", default="128,128")
    p.add_argument("--epochs", type=int, default=400)
    p.add_argument("--batch", type=int, default=0, help="mini-batch size (0: full batch)")
    p.add_argument("--patience", type=int, default=40, help="epochs without progress before the rate is halved")
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument("--holdout", type=int, default=5, help="hold out every N-th episode")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    import torch

    from kite_env.surrogate.model import SurrogateWing, output_errors
    from kite_env.surrogate.samples import OUTPUT_NAMES, WingSamples

    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    S = WingSamples.load(args.samples)
    X, Y = S.inputs, S.outputs
    ok = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(Y), axis=1)
    X, Y, group = X[ok], Y[ok], S.group[ok]
    val = (group % args.holdout) == args.holdout - 1
    if not val.any() or val.all():
        print("train_surrogate: error: the hold-out split leaves no training or no validation episodes",
              file=sys.stderr)
        return 2
    x_mean, x_std = X[~val].mean(0), X[~val].std(0) + 1e-6
    y_mean, y_std = Y[~val].mean(0), Y[~val].std(0) + 1e-9
    xt = torch.tensor((X - x_mean) / x_std, dtype=torch.float32)
    yt = torch.tensor((Y - y_mean) / y_std, dtype=torch.float32)
    sizes = [X.shape[1], *[int(h) for h in args.hidden.split(",")], Y.shape[1]]
    layers: list = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.Tanh())
    net = torch.nn.Sequential(*layers)
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=args.patience)
    x_tr, y_tr = xt[torch.from_numpy(~val)], yt[torch.from_numpy(~val)]
    va = torch.from_numpy(val)
    n_tr = len(x_tr)
    batch = n_tr if args.batch <= 0 else min(args.batch, n_tr)
    gen = torch.Generator().manual_seed(args.seed)
    best = (float("inf"), None, -1)
    t_start = time.perf_counter()
    for epoch in range(args.epochs):
        order = torch.randperm(n_tr, generator=gen) if batch < n_tr else torch.arange(n_tr)
        tot = 0.0
        for k in range(0, n_tr, batch):
            idx = order[k:k + batch]
            opt.zero_grad()
            loss = torch.mean((net(x_tr[idx]) - y_tr[idx]) ** 2)
            loss.backward()
            opt.step()
            tot += float(loss.detach()) * len(idx)
        loss = tot / n_tr
        with torch.no_grad():
            vloss = float(torch.mean((net(xt[va]) - yt[va]) ** 2))
        sched.step(vloss)
        if vloss < best[0]:
            best = (vloss, [t.detach().clone() for t in net.state_dict().values()], epoch)
        if epoch % 50 == 0 or epoch == args.epochs - 1:
            print(f"epoch {epoch:5d}  train {loss:.5f}  held-out {vloss:.5f}  lr {opt.param_groups[0]['lr']:.2e}",
                  flush=True)
    train_time = time.perf_counter() - t_start
    params = best[1]
    W = [params[2 * i].numpy().T.astype(float) for i in range(len(sizes) - 1)]
    b = [params[2 * i + 1].numpy().astype(float) for i in range(len(sizes) - 1)]
    model = SurrogateWing(W, b, x_mean, x_std, y_mean, y_std, X[~val].min(0), X[~val].max(0))
    errs = output_errors(Y[val], model.predict(X[val]))
    model.meta = {"samples": {k: v for k, v in S.meta.items() if k != "config"}, "config": S.meta.get("config"),
                  "hidden": sizes[1:-1], "epochs": args.epochs, "best_epoch": best[2], "lr": args.lr,
                  "batch": args.batch, "patience": args.patience, "holdout_every": args.holdout, "seed": args.seed,
                  "train_time_s": train_time, "torch": torch.__version__,
                  "n_train": int((~val).sum()), "n_heldout": int(val.sum()), "heldout_errors": errs}
    out = model.save(Path(args.out))
    print(f"\n{'output':<16} {'held-out RMS':>12}  unit")
    for name in OUTPUT_NAMES:
        unit = "deg" if name.startswith("alpha") else "N"
        v = errs["rms"][name] * (180.0 / np.pi if unit == "deg" else 1.0)
        print(f"{name:<16} {v:12.4g}  {unit}")
    print(f"\nbridle-force RMS error {errs['force_rms_N']:.1f} N = {100 * errs['force_rms_rel_traction']:.2f} % of "
          f"the mean traction {errs['mean_traction_N']:.0f} N ({int(val.sum())} held-out samples, "
          f"{int((~val).sum())} training; trained in {train_time:.0f} s); weights -> {out}")
    print(json.dumps({"force_rms_rel_traction": errs["force_rms_rel_traction"], "best_epoch": best[2],
                      "train_time_s": round(train_time, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
