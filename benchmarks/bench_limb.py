"""Limb models on held-out limbs (issue 20): end-point and per-joint errors, violations.

    python benchmarks/bench_limb.py [--limbs 10] [--n 6000] [--methods exact,uncoupled,geometric]
                                    [--forearm K]

Every held-out limb of :func:`models.limb_evaluation.held_out_limbs` (legs and arms with a
concave ball joint coupled to a hinge through 3-4 keyframes, a hinge, a two-axis joint; seeds
from ``HELD_OUT_LIMB_SEED``, none used to tune anything) is scored on
:func:`~models.limb_evaluation.held_out_postures` (a third uniform, a third near a boundary, a
third valid) by :func:`~models.evaluation.evaluate_model`. Methods:

``exact``      the limb oracle itself (the metrics' sanity check: every figure 0);
``uncoupled``  each coupled joint at its loosest limits (what ignoring the coupling costs);
``geometric``  the limb model (``models.limb_model``): the exact oracle compiled into one ONNX
               graph, run by onnxruntime (float32); also its file size, its graph's node
               count, single-call latency (median of 3000 ``correct_one`` calls) and batched
               throughput (median of 5 ``correction`` calls on 10,000 postures: chunks of
               1,024 on one worker per core; and the same 10,000 in one call on one thread);
``network``    the trained limb model: a distance field per coupled polygon swing
               (``models.nn.ndf``, seed 0), everything else exact in the same graph; the same
               figures plus its training time (wall and CPU seconds: a field alone on two
               cores trains on two threads, ``models.nn.ndf.fit_limb_fields``).
``network@F/F/…`` the same trained fields with other projection step fractions (e.g.
               ``network@0.5/0.5/0.5/1/1``, the shipped ones before 2026-11-28), accuracy only.

``--forearm K``: after them, K held-out arms whose elbow is a forearm joint
(:func:`~models.limb_evaluation.held_out_forearm_arms`: flexion and pronation–supination, the
shoulder coupled to the flexion; the 7-servo arm's chain), scored and summed up apart.

Single call: the median of 3000 ``correct_one`` calls cycling through the held-out postures,
and apart over the postures valid in every joint (where a live limb spends its time) and the
others; the network's projection steps run only when its field finds a direction outside, so
its valid postures' calls are the cheaper. The two models' single calls are measured in the
same run, interleaved, and their ratio printed (issue 39: network ≤ 50 µs and ≤ 1.2 ×
geometric), with the time a Python loop of 10⁷ additions took (how fast the machine was).
Node counts include the ``If`` branch's nodes (the top level's in brackets).

``--profile``: after each limb's single calls, each model's onnxruntime profile
(``SessionOptions.enable_profiling``) over 1000 single calls of the one-sample session: the
run's median (``model_run``) beside the kernels' sum (its nodes, ``If`` branches' included, the
``If`` nodes themselves not), their difference the per-run overhead, and the time by op type.
The profiler adds its own cost to every node (the unprofiled median is printed beside it), so
the shares by op type are the figures to read, not the sums.

``--single K``: instead, the same network family on K held-out single ball joints (concave
stars with twist, ``bench_accuracy``'s held-out set) beside today's default, the tabulated
field.

Prints one row per limb and method and the mean over limbs against the issue's targets.
"""

from __future__ import annotations

import argparse
import bisect
import collections
import dataclasses
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
import onnx
from common import additions_s

from models.evaluation import evaluate_model
from models.limb_evaluation import (
    held_out_forearm_arms,
    held_out_limbs,
    held_out_postures,
    uncoupled_model,
)
from models.limb_model import export_limb_model
from models.nn.ndf import fit_limb_fields, fit_swing_field
from models.onnx_io import latency_session, load_model, one_sample
from models.oracle import ConstraintOracle

TARGETS = (("end_mean_3d_error_pct", "end-point mean 3-D error %", "<= 0.5"),
           ("frac_invalid_violating_1deg", "invalid left > 1° out (fraction)", "<= 0.01"),
           ("valid_moved_deg", "valid inputs moved (mean °)", "<= 0.1"),
           ("end_p99_direction_error_deg", "p99 end-point direction error °", "<= 3"))


SPEED: dict[str, list[dict]] = {"geometric": [], "network": []}

#: the current limb's loaded models (geometric, network): their single calls are timed
#: together, interleaved (:func:`single_calls`)
LOADED: dict[str, object] = {}


#: the trained fields of the limb being scored: ``network@…`` reuses ``network``'s
TRAINED: dict[str, tuple] = {}


def _fields(limb) -> tuple[dict, dict, float]:
    if limb.name not in TRAINED:
        TRAINED.clear()
        c0 = time.process_time()
        fields, facts = fit_limb_fields(limb, seed=0)
        TRAINED[limb.name] = (fields, facts, time.process_time() - c0)
    return TRAINED[limb.name]


def method(name, limb, oracle, tmp: Path, q):
    if name == "exact":
        return oracle.correction
    if name == "uncoupled":
        return uncoupled_model(limb)
    if name.startswith("network@"):  # the same fields, other projection step fractions
        try:
            steps = tuple(float(x) for x in name.split("@", 1)[1].split("/"))
        except ValueError:
            raise SystemExit(f"--methods: {name!r}: expected network@F/F/..., e.g. "
                             "network@0.5/0.5/0.5/1/1") from None
        fields, facts, _ = _fields(limb)
        fields = {k: dataclasses.replace(v, steps=steps) for k, v in fields.items()}
        tag = "-".join(f"{x:g}" for x in steps)
        path = export_limb_model(limb, tmp / f"{limb.name}-network@{tag}.onnx", fields, facts)
        return load_model(path, limb).correction
    if name in ("geometric", "network"):
        fields, facts, cpu = None, None, 0.0
        if name == "network":
            fields, facts, cpu = _fields(limb)
        path = export_limb_model(limb, tmp / f"{limb.name}-{name}.onnx", fields, facts)
        model = load_model(path, limb)
        LOADED[name] = model
        f = facts or {}
        SPEED[name].append({**speed(model, q), "train_cpu_s": cpu,
                            "train_wall_s": f.get("seconds", 0.0),
                            "threads": f.get("workers", 0) * f.get("parts", 1)})
        return model.correction
    raise SystemExit(f"--methods: unknown method {name!r} (exact, uncoupled, geometric, "
                     f"network, network@F/F/...)")


def _count_nodes(graph) -> int:
    """Nodes of a graph and of its ``If`` branches."""
    return sum(1 + sum(_count_nodes(a.g) for a in node.attribute
                       if a.type == onnx.AttributeProto.GRAPH) for node in graph.node)


def single_calls(models: dict, q, valid) -> dict[str, dict[str, float]]:
    """Median single-call times (µs) of each model on the postures ``q``, all of them, the
    ``valid`` ones and the others: 3000 calls each, the models interleaved in rounds of 150
    calls (the same load for both)."""
    q32 = np.ascontiguousarray(q, dtype=np.float32)
    for m in models.values():
        for i in range(300):
            m.correct_one(q32[i % len(q32)])
    lat: dict[str, list[tuple[int, bool]]] = {k: [] for k in models}
    for r in range(20):
        for k, m in models.items():
            for i in range(r * 150, (r + 1) * 150):
                p = q32[i % len(q32)]
                t0 = time.perf_counter_ns()
                m.correct_one(p)
                lat[k].append((time.perf_counter_ns() - t0, bool(valid[i % len(q32)])))
    out = {}
    for k, v in lat.items():
        ok = [t for t, good in v if good]
        bad = [t for t, good in v if not good]
        out[k] = {"single_us": statistics.median(t for t, _ in v) / 1e3,
                  "single_valid_us": statistics.median(ok) / 1e3 if ok else float("nan"),
                  "single_invalid_us": statistics.median(bad) / 1e3 if bad else float("nan")}
    return out


def profile(name: str, model, q, calls: int = 1000) -> None:
    """Print an onnxruntime profile of ``model``'s one-sample session (module docstring)."""
    q32 = np.ascontiguousarray(q, dtype=np.float32)
    sess = latency_session(one_sample(onnx.load(str(model.path))), single=True,
                           profile=str(Path(tempfile.gettempdir()) / "bench-limb-profile"))
    feed = np.zeros((1, *q32.shape[1:]), dtype=np.float32)
    inp, out = model.contract.input, model.contract.output
    for i in range(calls + 200):
        feed[0] = q32[i % len(q32)]
        sess.run([out], {inp: feed})
    path = sess.end_profiling()
    events = json.loads(Path(path).read_text())
    Path(path).unlink()
    runs = sorted((e for e in events if e.get("cat") == "Session" and e["name"] == "model_run"),
                  key=lambda e: e["ts"])[200:]  # the warm-up's left out
    starts = [e["ts"] for e in runs]
    kernels = collections.defaultdict(float)
    by_op: dict[str, list[float]] = collections.defaultdict(lambda: [0.0, 0.0])
    for e in events:
        if e.get("cat") != "Node" or not e["name"].endswith("_kernel_time"):
            continue
        k = bisect.bisect_right(starts, e["ts"]) - 1
        op = e["args"].get("op_name", "?")
        if k < 0 or op == "If":  # an If's time is its branch's nodes, counted apart
            continue
        kernels[k] += e["dur"]
        by_op[op][0] += 1 / len(runs)
        by_op[op][1] += e["dur"] / len(runs)
    run = statistics.median(e["dur"] for e in runs)
    kern = statistics.median(kernels.values())
    total = sum(t for _, t in by_op.values())
    ops = sorted(by_op.items(), key=lambda kv: -kv[1][1])
    # unprofiled: the model's single call, and a one-node graph's (the per-run floor)
    ident = onnx.helper.make_model(onnx.helper.make_graph(
        [onnx.helper.make_node("Identity", [inp], [out])], "floor",
        [onnx.helper.make_tensor_value_info(inp, onnx.TensorProto.FLOAT, feed.shape)],
        [onnx.helper.make_tensor_value_info(out, onnx.TensorProto.FLOAT, feed.shape)]),
        opset_imports=[onnx.helper.make_opsetid("", 17)])
    ident.ir_version = 8
    floor = latency_session(ident.SerializeToString(), single=True)
    unprofiled: dict[str, list[int]] = {"model": [], "floor": []}
    for i in range(calls):
        p = q32[i % len(q32)]
        t0 = time.perf_counter_ns()
        model.correct_one(p)
        t1 = time.perf_counter_ns()
        floor.run([out], {inp: feed})
        unprofiled["model"].append(t1 - t0)
        unprofiled["floor"].append(time.perf_counter_ns() - t1)
    one, base = (statistics.median(unprofiled[k]) / 1e3 for k in ("model", "floor"))
    nodes = sum(n for n, _ in by_op.values())
    print(f"  profile {name}: unprofiled single call {one:.1f} µs, a one-node graph's "
          f"{base:.1f} µs (the per-run overhead), so {(one - base) / nodes:.2f} µs a node over "
          f"{nodes:.0f} nodes a run. Under the profiler: model_run {run:.0f} µs, its kernels "
          f"{kern:.0f} µs, the gap {run - kern:.0f} µs (the profiler's own cost dominates "
          f"both); by op type (nodes a run, share of the kernels' time): "
          + ", ".join(f"{op} {n:.0f} {t / total:.0%}" for op, (n, t) in ops[:12]))


def speed(model, q) -> dict:
    q32 = np.ascontiguousarray(q, dtype=np.float32)
    big = np.resize(q32, (10_000, *q32.shape[1:]))
    runs, one = [], []
    for _ in range(5):
        t0 = time.perf_counter()
        model.correction(big)
        runs.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        model.session.run(None, {"orientations": big})
        one.append(time.perf_counter() - t0)
    graph = onnx.load(str(model.path)).graph
    return {"bytes": model.size_bytes, "nodes": _count_nodes(graph), "top_nodes": len(graph.node),
            "per_s": len(big) / statistics.median(runs),
            "per_s_one_thread": len(big) / statistics.median(one)}


def single(k: int, n: int) -> None:
    """The distance-field network on single ball joints against today's default (the
    tabulated field, preset ``field``), on the held-out irregular boundaries of
    ``bench_accuracy`` (random stars with twist, seeds from ``HELD_OUT_SEED``)."""
    from models.evaluation import held_out_orientations, irregular_boundaries
    from models.field import FieldModel
    from models.kinds.ball import evaluate_ball
    from models.oracle import ConstraintOracle

    stars = [(name, c) for name, c in irregular_boundaries(k).items()
             if name.startswith("star")][:k]
    keys = (("mean_3d_error_pct", "mean 3-D error %", "<= 0.3"),
            ("frac_invalid_violating_1deg", "invalid > 1° out", "<= 0.005"),
            ("mean_identity_error_deg", "valid moved °", ""),
            ("p99_angular_error_deg", "p99 dir err °", ""))
    rows: dict[str, list[dict]] = {"field": [], "network": []}
    for name, c in stars:
        oracle = ConstraintOracle(c)
        q = held_out_orientations(c, n, 4321, oracle=oracle)
        table = FieldModel.from_constraint(c)
        c0 = time.process_time()
        net = fit_swing_field(c, np.random.default_rng(0))
        cpu = time.process_time() - c0
        lims = (c.twist.min, c.twist.max) if c.twist is not None else None

        def predict(x, net=net, c=c, lims=lims):
            def nearest(d):
                out, b = net.project(d, np.zeros(len(d)))
                return np.where(out, 1.0, -1.0), b
            x = x / np.linalg.norm(x, axis=1, keepdims=True)
            return evaluate_ball(x, np.asarray(c.limb_axis), nearest,
                                 None if lims is None else (lambda e: lims)).correction
        for label, model in (("field", table), ("network", predict)):
            r = evaluate_model(model, c, q=q, oracle=oracle)
            rows[label].append(r)
            print(f"{name:<10} {label:<8} " + " ".join(f"{r[k_]:8.3f}" for k_, _, _ in keys)
                  + (f"   trained {cpu:.0f} s CPU" if label == "network" else ""), flush=True)
    print(f"\nmean over {len(stars)} held-out single ball joints ({n} orientations each)")
    for key, label, goal in keys:
        print(f"{label:<22} {goal:>8} " + " ".join(
            f"{np.mean([r[key] for r in rows[m]]):10.3f}" for m in rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limbs", type=int, default=10)
    ap.add_argument("--n", type=int, default=6000, help="postures per limb")
    ap.add_argument("--methods", default="exact,uncoupled,geometric,network")
    ap.add_argument("--forearm", type=int, default=0, metavar="K",
                    help="also K held-out arms whose elbow is a forearm joint")
    ap.add_argument("--profile", action="store_true",
                    help="also each model's onnxruntime profile (module docstring)")
    ap.add_argument("--single", type=int, default=0, metavar="K",
                    help="instead: the network family on K held-out single ball joints "
                         "(concave stars with twist) beside the tabulated field")
    args = ap.parse_args()
    if args.single:
        single(args.single, args.n)
        return
    names = args.methods.split(",")
    print(f"a Python loop of 10^7 additions: {additions_s():.2f} s (how fast this machine "
          f"ran)")
    tmp = Path(tempfile.mkdtemp(prefix="bench-limb-"))
    families = [(f"{args.limbs} held-out limbs", held_out_limbs(args.limbs), 1000)
                ] if args.limbs else []
    if args.forearm:
        families.append((f"{args.forearm} held-out arms with a forearm elbow",
                         held_out_forearm_arms(args.forearm), 2000))
    for title, limbs, seed in families:
        score(title, limbs, seed, names, args.n, tmp, args.profile)




def score(title: str, limbs: dict, seed: int, names: list[str], n: int, tmp: Path,
          profiled: bool = False) -> None:
    """One family of limbs: a row per limb and method, the means, the models' figures."""
    for runs in SPEED.values():
        runs.clear()
    rows: dict[str, list[dict]] = {m: [] for m in names}
    print(f"\n{'limb':<18} {'method':<10} {'end %':>7} {'p99 end °':>9} {'left>1°':>8} "
          f"{'moved °':>8} {'max viol °':>10}  joint dir err ° (mean)")
    for i, (label, limb) in enumerate(limbs.items()):
        oracle = ConstraintOracle(limb)
        q = held_out_postures(limb, n, seed + i, oracle=oracle)
        LOADED.clear()
        for m in names:
            r = evaluate_model(method(m, limb, oracle, tmp, q), limb, q=q, oracle=oracle)
            rows[m].append(r)
            print(f"{label:<18} {m:<10} {r['end_mean_3d_error_pct']:7.3f} "
                  f"{r['end_p99_direction_error_deg']:9.2f} "
                  f"{r['frac_invalid_violating_1deg']:8.3f} "
                  f"{r['valid_moved_deg']:8.3f} {r['max_violation_deg']:10.2f}  "
                  f"{', '.join(f'{x:.2f}' for x in r['joint_mean_direction_error_deg'])}")
        if LOADED:
            calls = single_calls(LOADED, q, oracle.evaluate(q).valid.all(axis=1))
            for name, c in calls.items():
                SPEED[name][-1].update(c)
            if len(calls) == 2:
                g, nw = calls["geometric"], calls["network"]
                print(f"{label:<18} single call: network {nw['single_us']:.1f} µs, geometric "
                      f"{g['single_us']:.1f} µs, ratio {nw['single_us'] / g['single_us']:.2f}; "
                      f"valid postures {nw['single_valid_us']:.1f} / "
                      f"{g['single_valid_us']:.1f} µs, the others "
                      f"{nw['single_invalid_us']:.1f} / {g['single_invalid_us']:.1f} µs")
            if profiled:
                for name, model in LOADED.items():
                    profile(name, model, q)
    print(f"\nmean over {title} ({n} postures each)")
    print(f"{'target':<36} {'goal':>8} " + " ".join(f"{m:>10}" for m in names))
    for key, label, goal in TARGETS:
        vals = " ".join(f"{np.mean([r[key] for r in rows[m]]):10.3f}" for m in names)
        print(f"{label:<36} {goal:>8} {vals}")
    for name, runs in SPEED.items():
        if not runs:
            continue
        med = {k: statistics.median(x[k] for x in runs) for k in runs[0]}
        worst = max(x["train_wall_s"] for x in runs)
        train = (f"training {med['train_wall_s']:.0f} s median ({worst:.0f} s worst; "
                 f"{med['train_cpu_s']:.0f} s CPU on {med['threads']:.0f} thread(s)) "
                 f"(target <= 300)" if name == "network" else "no training")
        print(f"\n{name} limb model, median over {len(runs)} limbs: file "
              f"{med['bytes'] / 1e3:.0f} kB (target <= 2 MB), {med['nodes']:.0f} graph nodes "
              f"({med['top_nodes']:.0f} at the top level); onnxruntime single call "
              f"{med['single_us']:.0f} µs (target <= 50; valid postures "
              f"{med['single_valid_us']:.0f} µs, the others {med['single_invalid_us']:.0f}); "
              f"batched {med['per_s']:,.0f} limbs/s on {os.cpu_count()} cores (target >= "
              f"500,000), {med['per_s_one_thread']:,.0f} in one call on one thread; {train}")
    both = [(nw["single_us"], g["single_us"]) for nw, g in zip(SPEED["network"],
                                                              SPEED["geometric"], strict=False)]
    if both:
        ratios = [a / b for a, b in both]
        print(f"\nnetwork / geometric single call, same run: median ratio "
              f"{statistics.median(ratios):.2f} (target <= 1.2), per limb "
              f"{', '.join(f'{r:.2f}' for r in ratios)}")


if __name__ == "__main__":
    main()
