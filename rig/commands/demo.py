"""``rig demo``: the main job, end to end, on the simulated rig unless hardware ports are given.

1. **Constraint** — a patient-specific swing/twist boundary (default: the shipped irregular
   shoulder shape ``original``), validated and summarised.
2. **Dataset** — thesis-style patterns (even four-region distribution, valid-first order) with
   train/validation/test splits, written as ``.npz``.
3. **Train** — topology evolution + RPROP (preset ``best``), exported to ONNX with the
   constraint and metrics in its metadata.
4. **Evaluate** — the ONNX model through onnxruntime on fresh held-out orientations.
5. **Servo bus** — a Dynamixel Protocol 2.0 chain (simulated on a pty, or ``--dxl-port``):
   ping and a sync read/write cycle through the official ``dynamixel_sdk``.
6. **IMU** — a BNO055 (simulated on a pty, or ``--imu-port``) read through pyserial: fused
   quaternions, calibration status, achieved read rate.
"""

from __future__ import annotations

import time
from pathlib import Path

import click

QUICK_OVERRIDE = {
    "evolution": {"population": 8, "generations": 2},
    "training": {"max_epochs": 100, "min_epochs": 10},
    "data": {"train": 200, "validation": 100, "test": 500},
}


@click.command()
@click.option("--out", "out_dir", default="demo-output", show_default=True,
              type=click.Path(file_okay=False), help="Folder for the files the demo writes.")
@click.option("--constraint", "constraint_path", default=None, type=click.Path(dir_okay=False),
              help="Constraint YAML (default: the shipped shoulder shape 'original').")
@click.option("--preset", type=click.Choice(["best", "compact", "thesis", "fixed"]),
              default="best",
              show_default=True, help="Training preset.")
@click.option("--quick", is_flag=True, help="Tiny training run (smoke test).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--dxl-port", envvar="RIG_DXL_PORT", default=None,
              help="Real Dynamixel port (default: simulated chain). Env: RIG_DXL_PORT.")
@click.option("--dxl-ids", default="1,2,3", show_default=True,
              help="Servo IDs of the chain (1 to 3, parent to child).")
@click.option("--dxl-baud", type=int, default=1_000_000, show_default=True,
              help="Dynamixel bus baud rate (X-series factory default: 57600).")
@click.option("--imu-port", envvar="RIG_IMU_PORT", default=None,
              help="Real BNO055 UART port (default: simulated chip). Env: RIG_IMU_PORT.")
def demo(out_dir, constraint_path, preset, quick, seed, dxl_port, dxl_ids, dxl_baud,
         imu_port) -> None:
    """Run the main job end to end (simulated rig unless ports are given)."""
    ids = _parse_ids(dxl_ids)
    run_demo(Path(out_dir), constraint_path=constraint_path, preset=preset, quick=quick,
             seed=seed, dxl_port=dxl_port, dxl_ids=ids, dxl_baud=dxl_baud, imu_port=imu_port)


def _parse_ids(text: str) -> list[int]:
    from rig.errors import RigConfigError

    try:
        ids = [int(x) for x in text.split(",") if x.strip()]
    except ValueError as err:
        raise RigConfigError(f"--dxl-ids {text!r}: expected comma-separated integers") from err
    if not ids or any(not 0 <= i <= 252 for i in ids):
        raise RigConfigError(f"--dxl-ids {text!r}: IDs must be 0..252")
    if len(set(ids)) != len(ids):
        dup = next(i for i in ids if ids.count(i) > 1)
        raise RigConfigError(f"--dxl-ids {text!r}: duplicate ID {dup}")
    if len(ids) > 3:
        raise RigConfigError(f"--dxl-ids {text!r}: a servo chain has 1 to 3 joints")
    return ids


def _open_devices(dxl_port, ids, baud, imu_port, seed, echo):
    """Open (and check) the servo chain and the IMU before any long work: a wrong port, wrong
    baud, silent bus or duplicate ID fails here, in about a second, not after training."""
    from rig.devices.bno055 import Bno055
    from rig.devices.dynamixel import DynamixelChain
    from rig.devices.kinematics import ServoJoint

    if dxl_port is None:
        dxl_port = f"sim://dynamixel?ids={','.join(map(str, ids))}&model=XM430-W350"
        echo(f"  simulated XM430-W350 chain {ids}: {dxl_port}")
    axes = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))
    joints = [ServoJoint(i, axes[k]) for k, i in enumerate(ids)]
    chain = DynamixelChain(dxl_port, joints, baud=baud)
    try:
        for tip in chain.advice:
            echo(f"  note: {tip}")
        if imu_port is None:
            imu_port = f"sim://bno055?seed={seed}"
            echo(f"  simulated BNO055: {imu_port}")
        imu = Bno055(imu_port)
    except BaseException:
        chain.close()
        raise
    return chain, imu


def _step(echo, n: int, title: str) -> float:
    echo(f"\n[{n}/6] {title}")
    return time.perf_counter()


def run_demo(out: Path, *, constraint_path=None, preset="best", quick=False, seed=0,
             dxl_port=None, dxl_ids=(1, 2, 3), dxl_baud=1_000_000, imu_port=None,
             echo=click.echo) -> dict:
    """What ``rig demo`` does; returns the figures it printed (for tests)."""
    echo("[0/6] devices (opened and checked before the long work)")
    chain, imu = _open_devices(dxl_port, list(dxl_ids), dxl_baud, imu_port, seed, echo)
    try:
        return _run(out, chain, imu, constraint_path=constraint_path, preset=preset,
                    quick=quick, seed=seed, echo=echo)
    finally:
        try:
            imu.close()
        finally:
            chain.close()


def _run(out: Path, chain, imu, *, constraint_path, preset, quick, seed, echo) -> dict:
    import numpy as np

    from models.constraint import dump_constraint, load_constraint
    from models.datasets import quaternion_dataset, split_dataset
    from models.shapes import load_shape
    from rig.commands.train import run_evaluate, run_train

    out.mkdir(parents=True, exist_ok=True)
    report: dict = {}

    t = _step(echo, 1, "constraint")
    constraint = load_constraint(constraint_path) if constraint_path else load_shape("original")
    cpath = out / "constraint.yaml"
    dump_constraint(constraint, cpath)
    echo(constraint.summary())
    echo(f"  written to {cpath} ({time.perf_counter() - t:.2f} s)")

    t = _step(echo, 2, "dataset (thesis ch. 4: even distribution, valid patterns first)")
    ds = quaternion_dataset(constraint, 1000 if quick else 4000, np.random.default_rng(seed),
                            distribution="even", order="valid-first", hemisphere="w-positive")
    parts = split_dataset(ds, (0.7, 0.15, 0.15), np.random.default_rng(seed + 1))
    for name, part in zip(("train", "validation", "test"), parts, strict=True):
        part.save(out / f"{name}.npz")
    counts = ds.region_counts()
    echo(f"  {len(ds)} patterns, regions {counts}; splits "
         f"{'/'.join(str(len(p)) for p in parts)} written to {out}/{{train,validation,test}}.npz "
         f"({time.perf_counter() - t:.2f} s)")

    t = _step(echo, 3, f"train (preset {preset}{', quick' if quick else ''})")
    model_path = out / "model.onnx"
    config_path = None
    if quick:
        import yaml

        config_path = out / "quick.yaml"
        config_path.write_text(yaml.safe_dump(QUICK_OVERRIDE))
    trained = run_train(str(cpath), str(model_path), config_path=config_path, preset=preset,
                        seed=seed, echo=lambda s: echo("  " + s))
    report["train_metrics"] = trained.metrics
    echo(f"  ({time.perf_counter() - t:.1f} s)")

    t = _step(echo, 4, "evaluate the ONNX model on fresh held-out orientations (onnxruntime)")
    report["eval_metrics"] = run_evaluate(str(model_path), str(cpath), n=1000 if quick else 3000,
                                          seed=seed + 99, echo=lambda s: echo("  " + s))
    echo(f"  ({time.perf_counter() - t:.1f} s)")

    t = _step(echo, 5, "servo bus (Dynamixel Protocol 2.0 through dynamixel_sdk)")
    report["servos"] = _servo_check(chain, echo)
    echo(f"  ({time.perf_counter() - t:.2f} s)")

    t = _step(echo, 6, "IMU (BNO055 UART protocol through pyserial)")
    report["imu"] = _imu_check(imu, echo)
    echo(f"  ({time.perf_counter() - t:.2f} s)")
    echo(f"\ndone: files in {out}/")
    return report


def _servo_check(chain, echo) -> dict:
    found = {i: info.model_number for i, info in chain.servos.items()}
    echo("  ping: " + ", ".join(f"ID {i} -> {info.model} (firmware {info.firmware})"
                                for i, info in chain.servos.items()))
    n, t0 = 50, time.perf_counter()
    for _ in range(n):
        ticks = chain.read_ticks()  # raises after its retries: a silent bus is not a success
    rate = n / (time.perf_counter() - t0)
    pos = dict(zip(chain.ids, ticks.tolist(), strict=True))
    echo(f"  {n} {'fast ' if chain.fast else ''}sync reads of Present Position ({rate:.0f} Hz);"
         f" positions {pos} ticks; retries {chain.retried}")
    return {"found": found, "sync_read_hz": rate, "positions": pos}


def _imu_check(imu, echo) -> dict:
    import numpy as np

    from firmware_protocol.imu import bno055 as B

    chip = imu.chip_id()
    imu.set_mode(B.OperationMode.NDOF)
    n, t0 = 100, time.perf_counter()
    qs = np.array([imu.quaternion() for _ in range(n)])
    rate = n / (time.perf_counter() - t0)
    cal = imu.calibration()
    echo(f"  chip id 0x{chip:02X}; {n} quaternion reads at {rate:.0f} Hz; last "
         f"(w, x, y, z) = {np.round(qs[-1], 4).tolist()}; calibration sys/gyr/acc/mag = "
         f"{cal.system}/{cal.gyroscope}/{cal.accelerometer}/{cal.magnetometer}")
    return {"chip_id": chip, "read_hz": rate, "last": qs[-1].tolist()}
