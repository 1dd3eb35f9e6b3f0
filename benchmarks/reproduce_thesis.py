"""Reproduce the thesis's experiments with the ``thesis`` preset and write a Markdown report.

    python benchmarks/reproduce_thesis.py [--quick] [--repeats 5] [--jobs 2]
        [--out docs/thesis-reproduction.md] [--only regular,irregular,...]

Experiments (each repeated ``--repeats`` times with seeds 0 … r-1; metrics on 3000 unseen
patterns of the same distribution, :func:`models.metrics.evaluate`):

- ``regular``: radii 5, 20, 45, 90, 135, 150° with centres +X, +Y, +Z (thesis ch. 5, TABLE VI
  regular; TABLE V centre axis from the same runs).
- ``hemisphere``: TABLE IV — inputs forced to ``w ≥ 0`` versus the thesis's fix (all inputs on
  the centre's side of S³), +Y centre (for +X the two rules coincide), no in-graph
  canonicalisation, so the network sees exactly the data.
- ``irregular``: the five shipped shapes (TABLE VI irregular, TABLE VII).
- ``order``: valid-first / random / reversed (TABLE X), 45° cone.
- ``distribution``: even / clustered (TABLE XI), 45° cone.
- ``activation``: TABLE XII-XIII (hidden/output: spline/linear, evolved/evolved,
  sigmoid/linear, sigmoid/sigmoid) plus tanh, ReLU, leaky ReLU hidden nodes, 45° cone.
- ``svm``: ch. 6 — linear, polynomial, RBF, sigmoid kernels on quaternion and limb-direction
  features, 2000 training patterns, 45° cone and the 'original' shape.

Results stream to a JSON-lines file next to ``--out`` (so an interrupted run keeps what it
finished) and the report is rebuilt from it. ``--quick`` shrinks everything for a smoke test.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

RADII = (5, 20, 45, 90, 135, 150)
#: MSE figures are shown in the thesis's (SNNS) convention, SSE / patterns: 4 × our per-component
#: mean (:func:`models.metrics.mse`).
SNNS = 4.0
AXES = {"X": (1, 0, 0), "Y": (0, 1, 0), "Z": (0, 0, 1)}
SHAPES = ("highly-irregular", "small", "original", "large", "c-shape")
# TABLE VII's 3-D errors are endpoint distances (max 2.0): their mean 0.0432 / 2 = 2.16 % is
# the "irregular overall 2.15 %" of the text, so the percentages below are value / 2.
THESIS_VII = {"highly-irregular": "0.030 (1.50 %) / 9.33e-4 / 18.2",
              "small": "0.033 (1.65 %) / 9.14e-4 / 16.6",
              "original": "0.040 (2.00 %) / 1.24e-3 / 14",
              "large": "0.056 (2.80 %) / 2.98e-3 / 16.8",
              "c-shape": "0.057 (2.85 %) / 3.30e-3 / 16.2"}
THESIS_IV = {5: "+1.59e-5", 20: "−9.8e-5", 45: "−2.6e-5", 90: "+0.0040", 135: "+0.0043",
             150: "+0.0029"}


def experiments() -> list[dict]:
    ex = []
    for ax in AXES:
        for r in RADII:
            ex.append({"group": "regular", "name": f"cone {ax} {r}°", "cone": (AXES[ax], r),
                       "axis": ax, "radius": r, "override": {}})
    for r in RADII:
        for hemi in ("centre", "w-positive"):
            ex.append({"group": "hemisphere", "name": f"cone Y {r}° {hemi}",
                       "cone": (AXES["Y"], r), "radius": r, "hemi": hemi,
                       "override": {"data": {"hemisphere": hemi},
                                    "network": {"canonicalise": "none"}}})
    for s in SHAPES:
        ex.append({"group": "irregular", "name": s, "shape": s, "override": {}})
    same = ("regular", "cone X 45°")  # the thesis preset's defaults: one set of runs
    for o in ("valid-first", "random", "reversed"):
        ex.append({"group": "order", "name": o, "cone": (AXES["X"], 45),
                   "override": {"data": {"order": o}},
                   **({"alias": same} if o == "valid-first" else {})})
    for d in ("even", "clustered"):
        ex.append({"group": "distribution", "name": d, "cone": (AXES["X"], 45),
                   "override": {"data": {"distribution": d}},
                   **({"alias": same} if d == "even" else {})})
    evolved = ["sigmoid", "tanh", "gaussian", "sine", "linear"]
    acts = {
        "spline/linear": ({"hidden_activations": ["spline0", "spline1", "spline2", "spline3"],
                           "output_activations": ["linear"]},
                          {"evolve_activations": True, "evolve_splines": True}),
        "evolved/evolved": ({"hidden_activations": evolved, "output_activations": evolved},
                            {"evolve_activations": True}),
        "sigmoid/linear": ({}, {}),
        "sigmoid/sigmoid": ({"output_activations": ["sigmoid"]}, {}),
        "tanh/linear": ({"hidden_activations": ["tanh"]}, {}),
        "relu/linear": ({"hidden_activations": ["relu"]}, {}),
        "leaky_relu/linear": ({"hidden_activations": ["leaky_relu"]}, {}),
    }
    for name, (net, evo) in acts.items():
        ex.append({"group": "activation", "name": name, "cone": (AXES["X"], 45),
                   "override": {"network": net, "evolution": evo},
                   **({"alias": same} if name == "sigmoid/linear" else {})})
    for target in ("cone", "original"):
        for k in ("linear", "poly", "rbf", "sigmoid"):
            for feat in ("quaternion", "direction"):
                e = {"group": "svm", "name": f"{target} {k} {feat}", "kernel": k,
                     "feature": feat, "target": target}
                if target == "cone":
                    e["cone"] = (AXES["X"], 45)
                else:
                    e["shape"] = "original"
                ex.append(e)
    return ex


def _constraint(e):
    from models.constraint import JointConstraint
    from models.shapes import load_shape

    if "shape" in e:
        return load_shape(e["shape"])
    centre, r = e["cone"]
    return JointConstraint.cone(centre, r, name=f"cone-{r}")


def run_one(e: dict, seed: int, quick: bool) -> dict:
    from models.nn.config import get_config, merge
    from models.nn.train import train_correction

    c = _constraint(e)
    t0 = time.perf_counter()
    if e["group"] == "svm":
        return {**_run_svm(e, c, seed, quick), "seconds": time.perf_counter() - t0}
    over = merge({"evolution": {"repeats": 1}}, e["override"])
    if quick:
        over = merge(over, {"evolution": {"population": 8, "generations": 2},
                            "training": {"max_epochs": 60, "min_epochs": 20},
                            "data": {"train": 150, "validation": 75, "test": 300}})
    cfg = get_config("thesis", over)
    m = train_correction(c, cfg, np.random.default_rng(seed))
    return {**m.metrics, "epochs": m.result.epochs, "seconds": time.perf_counter() - t0}


def _run_svm(e, c, seed, quick):
    from models.nn.train import training_patterns
    from models.oracle import ConstraintOracle
    from models.svm import BinaryConstraintSVM

    rng = np.random.default_rng(seed)
    oracle = ConstraintOracle(c)
    n, nt = (300, 300) if quick else (2000, 3000)
    q, _ = training_patterns(c, n, rng, hemisphere="ambiguous", oracle=oracle)
    qt, _ = training_patterns(c, nt, rng, hemisphere="ambiguous", oracle=oracle)
    m = BinaryConstraintSVM(e["kernel"], feature=e["feature"]).fit(q, oracle.is_valid(q))
    acc = float(np.mean(m.predict(qt) == oracle.is_valid(qt)))
    return {"accuracy": acc, "support_vectors": len(m.support_vectors_)}


def _ms(vals, fmt):
    vals = [v for v in vals if v is not None and np.isfinite(v)]
    if not vals:
        return "—"
    sd = statistics.stdev(vals) if len(vals) > 1 else 0.0
    return f"{format(statistics.mean(vals), fmt)} ± {format(sd, fmt)}"


def _cell(rs):
    return (f"3-D {_ms([r['mean_3d_error_pct'] for r in rs], '.2f')} %, "
            f"MSE {_ms([SNNS * r['mse'] for r in rs], '.2e')}, "
            f"hidden {_ms([r['hidden'] for r in rs], '.1f')} (n={len(rs)})")


def report(results: list[dict], cmd: str, commit: str, elapsed: float) -> str:
    by: dict[tuple, list] = {}
    for r in results:
        by.setdefault((r["group"], r["name"]), []).append(r)
    L = ["# Thesis reproduction", "",
         f"Command: `{cmd}`  ", f"Commit: `{commit}`  ",
         f"Wall time: {elapsed / 60:.1f} min; preset `thesis` (TABLE II: population 50, "
         "20 generations, ≤ 500 RPROP epochs, stop MSE 0.001, Δ₀ 0.1, α₂ 0.01, max 20 hidden, "
         "500 training / 250 validation / 3000 test patterns). Each cell: mean ± sd over "
         "repeats (seeds 0…r−1). 3-D error = % of 2.0 (thesis metric); MSE of the unit "
         "correction quaternion on the test set in the thesis's SNNS convention (SSE / "
         "patterns, i.e. 4 × the per-component mean; the stopping MSE 0.001 is read the same "
         "way).", "",
         "| experiment | thesis figure | ours (mean ± sd) |", "|---|---|---|"]

    def row(exp, thesis, rs):
        if rs:
            L.append(f"| {exp} | {thesis} | {_cell(rs)} |")

    reg = [r for r in results if r["group"] == "regular"]
    if reg:
        L.append(f"| regular, all radii & centres: avg / max 3-D error | 0.99 % / 11.67 % | "
                 f"{_ms([r['mean_3d_error_pct'] for r in reg], '.2f')} % / "
                 f"{max(r['max_3d_error_pct'] for r in reg):.2f} % (n={len(reg)}) |")
        L.append(f"| regular: patterns > 2 % error | 3.7e-4 % | "
                 f"{_ms([100 * r['frac_above_2pct'] for r in reg], '.2f')} % |")
        mses = [SNNS * r["mse"] for r in reg]
        L.append(f"| TABLE VI regular MSE min / max / avg | 4.79e-5 / 7.86e-4 / 3.31e-4 | "
                 f"{min(mses):.2e} / {max(mses):.2e} / {statistics.mean(mses):.2e} |")
        L.append(f"| regular: hidden nodes | 16 | {_ms([r['hidden'] for r in reg], '.1f')} |")
        for ax, fig in (("Y", "0.087"), ("X", "0.120"), ("Z", "0.236")):
            row(f"TABLE V centre {ax} (thesis: 4-D difference)", fig,
                [r for r in reg if r.get("axis") == ax])
        for ax in AXES:
            for rad in RADII:
                row(f"regular {ax} {rad}°", "—", by.get(("regular", f"cone {ax} {rad}°"), []))
    for rad in RADII:
        a = by.get(("hemisphere", f"cone Y {rad}° centre"), [])
        b = by.get(("hemisphere", f"cone Y {rad}° w-positive"), [])
        if a and b:
            d = SNNS * (statistics.mean(r["mse"] for r in b) - statistics.mean(r["mse"] for r in a))
            L.append(f"| TABLE IV forcing w ≥ 0, MSE change, {rad}° | {THESIS_IV[rad]} | "
                     f"{d:+.2e} (forced {_ms([SNNS * r['mse'] for r in b], '.2e')} vs centre "
                     f"side {_ms([SNNS * r['mse'] for r in a], '.2e')}) |")
    irr = [r for r in results if r["group"] == "irregular"]
    if irr:
        L.append(f"| TABLE VI irregular avg MSE / hidden | 1.24e-3 / 18.4 | "
                 f"{_ms([SNNS * r['mse'] for r in irr], '.2e')} / "
                 f"{_ms([r['hidden'] for r in irr], '.1f')} |")
        L.append(f"| irregular overall avg / max 3-D error | 2.15 % / 24.71 % | "
                 f"{_ms([r['mean_3d_error_pct'] for r in irr], '.2f')} % / "
                 f"{max(r['max_3d_error_pct'] for r in irr):.2f} % |")
        L.append(f"| irregular: patterns > 7.5 % error | 0.032 % | "
                 f"{_ms([100 * r['frac_above_7_5pct'] for r in irr], '.2f')} % |")
        for s in SHAPES:
            row(f"TABLE VII {s} (3-D error / MSE / hidden)", THESIS_VII[s],
                by.get(("irregular", s), []))
    for o, fig in (("valid-first", "4.88e-4"), ("random", "6.43e-4"), ("reversed", "6.49e-4")):
        row(f"TABLE X order {o} (MSE)", fig, by.get(("order", o), []))
    for d, fig in (("even", "MSE 4.88e-4, hidden 17"), ("clustered", "MSE 7.85e-4, hidden 17.8")):
        row(f"TABLE XI distribution {d}", fig, by.get(("distribution", d), []))
    for a, fig in (("spline/linear", "5.46e-4; 14.4 hidden"),
                   ("evolved/evolved", "6.19e-4; 14.6 hidden"),
                   ("sigmoid/linear", "6.22e-4; 17 hidden"),
                   ("sigmoid/sigmoid", "1.01e-1; 8.6 hidden"),
                   ("tanh/linear", "—"), ("relu/linear", "—"), ("leaky_relu/linear", "—")):
        row(f"TABLE XII-XIII activations {a} (MSE)", fig, by.get(("activation", a), []))
    svm = [r for r in results if r["group"] == "svm"]
    for (g, name), rs in sorted(by.items()):
        if g == "svm":
            L.append(f"| ch. 6 SVM {name}: test accuracy | poly & RBF best; quaternion > 3-D | "
                     f"{_ms([100 * r['accuracy'] for r in rs], '.2f')} %, "
                     f"{_ms([r['support_vectors'] for r in rs], '.0f')} SVs (n={len(rs)}) |")
    del svm
    secs = [r["seconds"] for r in results if r["group"] not in ("svm",)]
    if secs:
        L += ["", f"Per-experiment wall time (evolution + data + evaluation, one core per "
                  f"job): median {statistics.median(secs):.1f} s, max {max(secs):.1f} s "
                  "(thesis: 16-18 h)."]
    L += ["", NEW_METHOD]
    return "\n".join(L) + "\n"


#: The method that replaced the thesis's network as the default (``rig train``, preset
#: ``field``), measured by ``benchmarks/bench_accuracy.py`` (issue 9's protocol, not the
#: thesis's pattern sets); kept in the generated report so a re-run does not drop it.
NEW_METHOD = """## Beside the thesis: the swing-twist factored field model (preset `field`)

`models/field.py` (details and the side-by-side measurement: `docs/learned-constraints.md`):
the swing correction sampled from the exact oracle on a ~0.5° grid on S² (nearest node,
inside the ONNX graph), the twist clamped exactly in the graph. Held-out boundaries and
orientations of issue 9 (half uniform on SO(3), half within 20° of the boundary, 10 000 per
boundary, through onnxruntime; `python benchmarks/bench_accuracy.py`):

| | thesis (its own test sets) | preset `field` | analytic peer (van den Bergen) |
|---|---|---|---|
| regular, mean 3-D error | 0.99 % | 0.084 % (18 cones, 5-150°, X/Y/Z) | 0.000 % (exact for cones) |
| irregular, mean 3-D error | 2.15 % (no twist) | 0.143 % (5 shapes + 20 stars, twist) | 6.07 % |
| invalid inputs left > 1° outside, irregular | — | 0.18 % | 43.7 % |
| build / training time | 16-18 h per experiment | ~1 s | — |
"""


def _with_aliases(done: list[dict], aliases: list[dict]) -> list[dict]:
    """Add copies of the runs of identical configurations under their other names."""
    out = [r for r in done if (r["group"], r["name"]) not in
           {(a["group"], a["name"]) for a in aliases}]
    for a in aliases:
        out += [{**r, "group": a["group"], "name": a["name"]} for r in done
                if (r["group"], r["name"]) == a["alias"]]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("docs/thesis-reproduction.md"))
    ap.add_argument("--only", default="", help="comma-separated groups")
    ap.add_argument("--resume", action="store_true", help="keep finished results")
    ap.add_argument("--append", type=Path, default=None,
                    help="Markdown file appended to the report (notes, other benchmarks)")
    ap.add_argument("--report-only", action="store_true",
                    help="rebuild the Markdown from the JSON-lines results and exit")
    args = ap.parse_args(argv)
    if args.quick:
        args.repeats = min(args.repeats, 2)
    exps = experiments()
    if args.only:
        keep = set(args.only.split(","))
        exps = [e for e in exps if e["group"] in keep]
    jsonl = args.out.with_suffix(".jsonl")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    done: list[dict] = []
    if args.resume and jsonl.exists():
        done = [json.loads(line) for line in jsonl.read_text().splitlines() if line.strip()]
    if args.report_only:
        done = [json.loads(line) for line in jsonl.read_text().splitlines() if line.strip()]
        prev = args.out.read_text() if args.out.exists() else ""
        head = [ln for ln in prev.splitlines() if ln.startswith(("Command:", "Commit:", "Wall"))]
        cmd0 = head[0].split("`")[1] if head else "?"
        commit0 = head[1].split("`")[1] if len(head) > 1 else "?"
        wall = float(head[2].split()[2]) * 60 if len(head) > 2 else 0.0
        aliases = [e for e in exps if "alias" in e]
        text = report(_with_aliases(done, aliases), cmd0, commit0, wall)
        if args.append:
            text += "\n" + args.append.read_text()
        args.out.write_text(text)
        print(f"wrote {args.out}")
        return
    have = {(r["group"], r["name"], r["seed"]) for r in done}
    # seeds outermost: if the run is cut short every experiment has its first repeats
    jobs = [(e, s) for s in range(args.repeats) for e in exps
            if "alias" not in e and (e["group"], e["name"], s) not in have]
    aliases = [e for e in exps if "alias" in e]
    cmd = "python " + " ".join([sys.argv[0], *(argv if argv is not None else sys.argv[1:])])
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=False).stdout.strip() or "unknown"
    except OSError:
        commit = "unknown"
    t0 = time.perf_counter()
    mode = "a" if args.resume else "w"
    with jsonl.open(mode) as fh, ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futs = {pool.submit(run_one, e, s, args.quick): (e, s) for e, s in jobs}
        for k, f in enumerate(as_completed(futs), 1):
            e, s = futs[f]
            res = {"group": e["group"], "name": e["name"], "seed": s,
                   **{k2: e[k2] for k2 in ("axis", "radius", "hemi") if k2 in e}, **f.result()}
            done.append(res)
            fh.write(json.dumps(res) + "\n")
            fh.flush()
            print(f"[{k}/{len(jobs)}] {e['group']:<12} {e['name']:<28} seed {s}  "
                  f"{res.get('mean_3d_error_pct', res.get('accuracy', 0)):.4g}  "
                  f"{res['seconds']:.1f} s", flush=True)
            args.out.write_text(report(_with_aliases(done, aliases), cmd, commit,
                                       time.perf_counter() - t0))
    args.out.write_text(report(_with_aliases(done, aliases), cmd, commit,
                               time.perf_counter() - t0))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
