"""OpenSim ``.sto`` and CSV import/export (rig.store.io)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rig.cli import main
from rig.errors import RigConfigError
from rig.store import SampleWriter, open_store
from rig.store import schema as S
from rig.store.io import (
    NORM_TOLERANCE,
    RAW_CSV_COLUMNS,
    OrientationTable,
    export_session,
    read_csv,
    read_orientations,
    read_samples_csv,
    read_sto,
    session_table,
    write_csv,
    write_samples_csv,
    write_sto,
)

DATA = Path(__file__).parent / "data"
OPENSENSE = DATA / "opensense_orientations.sto"


def _unit(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _table(rng, n=200, labels=("thorax_imu", "humerus_imu")):
    # awkward floats on purpose: tiny, large and non-terminating times
    t = np.cumsum(rng.uniform(1e-4, 0.01, n)) + 1234.5678901234567
    return OrientationTable(time=t, columns={lab: _unit(rng, n) for lab in labels})


def test_sto_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(7)
    table = _table(rng)
    table.columns["thorax_imu"][0] = [1.0, 0.0, 0.0, 1e-300]  # subnormal-ish extremes survive
    table.meta["rig_session"] = "12"
    path = tmp_path / "rec.sto"
    write_sto(path, table)
    head = path.read_text().splitlines()[:7]
    assert head[1:4] == ["DataType=Quaternion", "version=3", "OpenSimVersion=4.5"]
    assert head[0].startswith("DataRate=") and "endheader" in head
    back = read_sto(path)
    np.testing.assert_array_equal(back.time, table.time)
    assert back.labels == table.labels
    for lab in table.labels:
        np.testing.assert_array_equal(back.columns[lab], table.columns[lab])
    assert back.meta["rig_session"] == "12"
    assert back.rate_hz == pytest.approx(1 / np.median(np.diff(table.time)), rel=1e-6)


def test_csv_round_trips_are_exact(tmp_path):
    rng = np.random.default_rng(8)
    table = _table(rng)
    write_csv(tmp_path / "wide.csv", table)
    assert (tmp_path / "wide.csv").read_text().splitlines()[0] == (
        "t_s,thorax_imu_w,thorax_imu_x,thorax_imu_y,thorax_imu_z,"
        "humerus_imu_w,humerus_imu_x,humerus_imu_y,humerus_imu_z")
    back = read_csv(tmp_path / "wide.csv")
    np.testing.assert_array_equal(back.time, table.time)
    for lab in table.labels:
        np.testing.assert_array_equal(back.columns[lab], table.columns[lab])
    one = OrientationTable(time=table.time, columns={"target": table.columns["thorax_imu"]})
    write_csv(tmp_path / "single.csv", one, single=True)
    assert (tmp_path / "single.csv").read_text().startswith("t_s,w,x,y,z\n")
    back = read_orientations(tmp_path / "single.csv")
    np.testing.assert_array_equal(back.get("orientation"), one.columns["target"])


def test_reads_an_opensense_style_file():
    """Shaped like OpenSim's STOFileAdapter output and the OpenSense example trials: a bare
    first header line, DataRate/DataType/version/OpenSimVersion, more IMU columns than used,
    16 significant digits, a trial that does not start at 0."""
    table = read_sto(OPENSENSE)
    assert table.rate_hz == 100.0
    assert table.labels == ["pelvis_imu", "torso_imu", "humerus_r_imu", "ulna_r_imu",
                            "radius_r_imu"]
    assert len(table) == 12 and table.time[0] == 7.25
    assert table.meta["OpenSimVersion"].startswith("4.5")
    q = table.get("humerus_r")  # with or without the _imu suffix
    assert q is table.get("humerus_r_imu") and q.shape == (12, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    with pytest.raises(RigConfigError, match=r"no column 'femur_r'.*pelvis_imu"):
        table.get("femur_r")


def test_reads_windows_line_endings_extra_header_lines_and_non_quaternion_columns(tmp_path):
    lines = OPENSENSE.read_text().splitlines()
    header, body = lines[:lines.index("endheader")], lines[lines.index("endheader") + 1:]
    extra = ["Xsens MT Manager export", "nRows=12", "nColumns=6", "", "inDegrees=no"]
    labels = body[0] + "\tframe\tacc_torso"
    rows = [r + f"\t{k}\t0.1,9.8,0.2" for k, r in enumerate(body[1:])]
    text = "\r\n".join(header + extra + ["endheader", labels, *rows, "", ""])
    p = tmp_path / "win.sto"
    p.write_bytes(text.encode())
    table = read_sto(p)
    ref = read_sto(OPENSENSE)
    assert table.labels == ref.labels
    assert table.meta["ignored_columns"] == "frame,acc_torso"
    assert table.meta["nRows"] == "12"
    for lab in ref.labels:
        np.testing.assert_array_equal(table.columns[lab], ref.columns[lab])


def _sto(tmp_path, rows, labels="time\tthorax_imu\thumerus_imu", header=None):
    header = header or ["DataRate=100.000000", "DataType=Quaternion", "version=3", "endheader"]
    p = tmp_path / "bad.sto"
    p.write_text("\n".join([*header, labels, *rows]) + "\n")
    return p


GOOD = "1,0,0,0"


@pytest.mark.parametrize(
    ("row", "message"),
    [
        (f"0.02\tnan,0,0,0\t{GOOD}", "bad.sto:7: column thorax_imu: NaN in quaternion"),
        (f"0.02\t{GOOD}\t0,0,0,0", "bad.sto:7: column humerus_imu: zero quaternion"),
        (f"0.02\t{GOOD}\t0.9,0,0,0", "bad.sto:7: column humerus_imu: quaternion norm 0.9 is "
                                     "not 1"),
        (f"0.02\t{GOOD}\t2,0,0,0", "refusing to renormalise"),
        (f"0.02\t{GOOD}", "bad.sto:7: 2 cells, expected 3"),
        (f"0.02\t{GOOD}\t1,0,0", "bad.sto:7: column humerus_imu: 3 components, expected 4"),
        (f"0.02\t{GOOD}\t1,0,zero,0", "bad.sto:7: column humerus_imu: 'zero' is not a number"),
        (f"0.02\t{GOOD}\tinf,0,0,0", "bad.sto:7: column humerus_imu: infinite"),
        (f"abc\t{GOOD}\t{GOOD}", "bad.sto:7: time: 'abc' is not a number"),
        (f"0.01\t{GOOD}\t{GOOD}", "bad.sto:7: time 0.01 does not increase"),
    ],
)
def test_bad_sto_rows_are_named_by_line(tmp_path, row, message):
    p = _sto(tmp_path, [f"0.01\t{GOOD}\t{GOOD}", row])
    with pytest.raises(RigConfigError) as err:
        read_sto(p)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_near_unit_quaternions_are_kept_as_written(tmp_path):
    off = 1.0 + 0.5 * NORM_TOLERANCE
    p = _sto(tmp_path, [f"0.01\t{off!r},0,0,0\t0.7071,0.7071,0,0"])
    table = read_sto(p)
    assert table.get("thorax")[0, 0] == off  # not renormalised
    assert table.get("humerus")[0].tolist() == [0.7071, 0.7071, 0.0, 0.0]


@pytest.mark.parametrize(
    ("header", "labels", "message"),
    [
        (["DataRate=100", "DataType=Quaternion"], "time\tthorax_imu", "no 'endheader'"),
        (["DataType=double", "endheader"], "time\tthorax_imu", "DataType=double, expected"),
        (["endheader"], "t\tthorax_imu", "first column must be 'time'"),
        (["endheader"], "time\tframe", "no quaternion columns"),
    ],
)
def test_bad_sto_headers(tmp_path, header, labels, message):
    rows = ["0.01\t3"] if labels.endswith("frame") else [f"0.01\t{GOOD}"]
    with pytest.raises(RigConfigError, match=message):
        read_sto(_sto(tmp_path, rows, labels=labels, header=header))


def test_bad_csv_rows_are_named_by_line(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t_s,w,x,y,z\n0.0,1,0,0,0\n0.1,NaN,0,0,0\n")
    with pytest.raises(RigConfigError, match=r"t\.csv:3: orientation: NaN in quaternion"):
        read_csv(p)
    p.write_text("t_s,w,x,y,z\n0.0,1,0,0,0\n0.1,0,0,0\n")
    with pytest.raises(RigConfigError, match=r"t\.csv:3: 4 cells, expected 5"):
        read_csv(p)
    p.write_text("t_s,name,w,x,y,z\n0.0,humerus,1,0,0,0\n0.1,humerus,0,0,0,0\n")
    with pytest.raises(RigConfigError, match=r"t\.csv:3: humerus: zero quaternion"):
        read_csv(p)
    p.write_text("t_s,a,b\n0.0,1,2\n")
    with pytest.raises(RigConfigError, match="no quaternion columns"):
        read_csv(p)
    with pytest.raises(RigConfigError, match="unknown format"):
        read_orientations(tmp_path / "x.c3d")


def test_long_csv_is_aligned_without_interpolation(tmp_path):
    rng = np.random.default_rng(3)
    n = 400
    t = np.arange(n) / 400.0
    th = np.r_[0:100, 110:n]  # thorax: 10 samples lost -> the sparser series leads
    qa, qb = _unit(rng, th.size), _unit(rng, n - 1)
    s = {
        "t": np.r_[t[th], t[1:] + 0.0003],  # humerus: 0.3 ms later, its first sample missing
        "device_t": np.full(th.size + n - 1, np.nan),
        "name": np.array(["thorax"] * th.size + ["humerus"] * (n - 1), dtype=object),
        "kind": np.array(["sensor"] * (th.size + n - 1), dtype=object),
        "q": np.r_[qa, qb],
        "status": np.zeros(th.size + n - 1, dtype=np.int64),
    }
    write_samples_csv(tmp_path / "long.csv", s)
    back = read_samples_csv(tmp_path / "long.csv")
    for k in ("t", "q", "status"):
        np.testing.assert_array_equal(back[k], s[k])
    assert list(back["name"]) == list(s["name"])
    assert "acc_x" not in (tmp_path / "long.csv").read_text().splitlines()[0]
    assert back["raw"].shape == (s["t"].size, 9) and np.isnan(back["raw"]).all()
    table = read_csv(tmp_path / "long.csv")
    assert table.meta["aligned_dropped"] == "1"  # thorax at t=0 has no humerus partner
    np.testing.assert_array_equal(table.time, t[th[1:]])
    np.testing.assert_array_equal(table.get("thorax"), qa[1:])
    np.testing.assert_array_equal(table.get("humerus"), qb[th[1:] - 1])  # nearest, not mixed


def _recorded(store, rng, n=500, shared=True):
    pid = store.patients.add("P-77")
    sid = store.sessions.start(pid, rig_name="sim-imu", joint="shoulder", side="left")
    t = 50.0 + np.arange(n) / 400.0
    q = {"thorax": _unit(rng, n), "humerus": _unit(rng, n)}
    with SampleWriter(store, sid) as w:
        for k in range(n):  # interleaved, as a reader thread delivers them
            w.add(t[k], k / 400.0, "thorax", "sensor", q["thorax"][k], 3)
            tk = t[k] if shared else t[k] + 0.0004
            w.add(tk, k / 400.0, "humerus", "sensor", q["humerus"][k], 2)
    store.sessions.end(sid)
    return sid, t, q


def test_session_export_import_is_exact(tmp_path):
    rng = np.random.default_rng(11)
    with open_store(tmp_path / "r.db") as store:
        sid, t, q = _recorded(store, rng)
        info = export_session(store, sid, "sto", tmp_path / "s.sto")
        assert info["rows"] == 500 and info["dropped_rows"] == 0
        table = read_sto(tmp_path / "s.sto")
        assert table.labels == ["thorax_imu", "humerus_imu"]
        np.testing.assert_array_equal(table.time, t)
        np.testing.assert_array_equal(table.get("thorax"), q["thorax"])
        np.testing.assert_array_equal(table.get("humerus"), q["humerus"])
        assert table.meta["rig_patient"] == "P-77" and table.meta["rig_side"] == "left"
        assert table.rate_hz == pytest.approx(400.0)
        export_session(store, sid, "csv", tmp_path / "s.csv")
        back = read_samples_csv(tmp_path / "s.csv")
        s = store.samples.read(sid)
        for k in ("t", "device_t", "q", "status"):
            np.testing.assert_array_equal(back[k], s[k])
        assert list(back["name"]) == list(s["name"]) and list(back["kind"]) == list(s["kind"])
        with pytest.raises(RigConfigError, match="--format"):
            export_session(store, sid, "c3d", tmp_path / "x")


def test_session_export_aligns_sensors_with_their_own_clocks(tmp_path):
    rng = np.random.default_rng(12)
    with open_store(tmp_path / "r.db") as store:
        sid, _, q = _recorded(store, rng, n=300, shared=False)
        table, dropped = session_table(store, sid)
        assert dropped == 0 and len(table) == 300
        np.testing.assert_array_equal(table.get("thorax"), q["thorax"])
        np.testing.assert_array_equal(table.get("humerus"), q["humerus"])
        empty = store.sessions.start(store.patients.ensure("P-77"))
        with pytest.raises(RigConfigError, match="no samples"):
            export_session(store, empty, "sto", tmp_path / "e.sto")


@pytest.mark.parametrize("device_clock", [True, False])
def test_session_with_batch_timestamps_exports_as_sto(tmp_path, device_clock, capsys):
    # a reader stamps each batch of frames with one host time (an IMU session has ~18
    # repeated times a minute per sensor); the device stamps every frame, when it has a clock
    rng = np.random.default_rng(13)
    n = 240
    t = 30.0 + np.repeat(np.arange(n // 8) * 8 / 400.0, 8)  # one host time per batch of 8
    dev = np.arange(n) / 400.0 + 7.0 if device_clock else np.full(n, np.nan)
    q = {"thorax": _unit(rng, n), "humerus": _unit(rng, n)}
    db = tmp_path / "b.db"
    with open_store(db) as store:
        sid = store.sessions.start(store.patients.add("P-78"), rig_name="sim-imu")
        with SampleWriter(store, sid) as w:
            for k in range(n):
                w.add(t[k], dev[k], "thorax", "sensor", q["thorax"][k], 3)
                w.add(t[k], dev[k], "humerus", "sensor", q["humerus"][k], 3)
        store.sessions.end(sid)
    with pytest.raises(SystemExit) as info:
        main(["export", "--db", str(db), "--session", str(sid), "--format", "sto", "--out",
              str(tmp_path / "b.sto")])
    assert info.value.code == 0, capsys.readouterr().err
    table = read_sto(tmp_path / "b.sto")
    assert len(table) == n and (np.diff(table.time) > 0).all()
    np.testing.assert_array_equal(table.get("thorax"), q["thorax"])
    np.testing.assert_array_equal(table.get("humerus"), q["humerus"])
    if device_clock:  # the device's own spacing, on the host clock
        np.testing.assert_allclose(np.diff(table.time), 1 / 400.0, atol=1e-9)
        assert table.meta["rig_time"] == "device clock on the host clock"
    else:  # no device clock: each batch spread evenly up to the next
        assert table.meta["rig_time"] == "host, repeated times spread evenly"
        np.testing.assert_allclose(table.time[:8], 30.0 + np.arange(8) / 400.0, atol=1e-12)


def _samples_with_raw(rng, n=300):
    raw = rng.normal(size=(n, 9)) * np.repeat([9.81, 1.0, 48.0], 3)
    raw[::7] = np.nan  # samples without a raw reading
    raw[3, 6:] = np.nan  # one without its magnetometer
    raw[5, 0] = 1e-310  # subnormal: still exact
    return {
        "t": 10.0 + np.arange(n) / 400.0, "device_t": np.arange(n) / 400.0,
        "name": np.array(["humerus"] * n, dtype=object),
        "kind": np.array(["sensor"] * n, dtype=object),
        "q": _unit(rng, n), "status": np.full(n, 3, dtype=np.int64), "raw": raw,
    }


def test_long_csv_keeps_raw_readings_exactly(tmp_path):
    assert RAW_CSV_COLUMNS == S.RAW_COLUMNS  # the file's names are the store's
    s = _samples_with_raw(np.random.default_rng(21))
    write_samples_csv(tmp_path / "raw.csv", s)
    lines = (tmp_path / "raw.csv").read_text().splitlines()
    assert lines[0] == ("t_s,device_t_s,name,kind,w,x,y,z,status,"
                        "acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,mag_x,mag_y,mag_z")
    assert lines[1].endswith(",3" + "," * 9)  # sample 0: no raw reading, empty cells
    back = read_samples_csv(tmp_path / "raw.csv")
    for k in ("t", "device_t", "q", "status", "raw"):
        np.testing.assert_array_equal(back[k], s[k])  # bit-exact, NaN where NaN
    table = read_csv(tmp_path / "raw.csv")  # the orientation reader ignores them
    np.testing.assert_array_equal(table.get("humerus"), s["q"])


def test_long_csv_raw_columns_come_as_all_nine(tmp_path):
    p = tmp_path / "part.csv"
    p.write_text("t_s,name,w,x,y,z,acc_x,acc_y,acc_z\n0.0,humerus,1,0,0,0,0,0,9.81\n")
    with pytest.raises(RigConfigError, match=r"raw columns come as all nine.*missing gyr_x"):
        read_samples_csv(p)
    head = "t_s,name,w,x,y,z," + ",".join(RAW_CSV_COLUMNS) + "\n"
    p.write_text(head + "0.0,humerus,1,0,0,0,0,0,9.81,0,0,x,0,0,0\n")
    with pytest.raises(RigConfigError, match=r"part.csv:2: gyr_z: 'x' is not a number"):
        read_samples_csv(p)
    p.write_text(head + "0.0,humerus,1,0,0,0,0,0,inf,0,0,0,0,0,0\n")
    with pytest.raises(RigConfigError, match=r"part.csv:2: acc_z: inf is not a finite"):
        read_samples_csv(p)
    p.write_text(head + "0.0,humerus,1,0,0,0,0,0,9.81,nan,,0,1,2,3\n")
    np.testing.assert_array_equal(read_samples_csv(p)["raw"],
                                  [[0, 0, 9.81, np.nan, np.nan, 0, 1, 2, 3]])


def test_session_with_raw_exports_its_raw_readings(tmp_path, capsys):
    """``rig export --format csv`` keeps the raw readings; .sto carries orientations only."""
    from rig.cli import main

    rng = np.random.default_rng(22)
    s = _samples_with_raw(rng, 200)
    with open_store(tmp_path / "r.db") as store:
        sid = store.sessions.start(store.patients.add("P-R"))
        with SampleWriter(store, sid) as w:
            w.add_many(s["t"], s["device_t"], "humerus", "sensor", s["q"], 3, raw=s["raw"])
            w.add_many(s["t"], None, "thorax", "sensor", _unit(rng, 200))  # no raw
        store.sessions.end(sid)
        stored = store.samples.read(sid)
    out = tmp_path / "s.csv"
    with pytest.raises(SystemExit) as exc:
        main(["export", "--db", str(tmp_path / "r.db"), "--session", str(sid),
              "--format", "csv", "--out", str(out)])
    assert exc.value.code == 0 and "wrote 400 rows" in capsys.readouterr().out
    assert out.read_text().splitlines()[0].endswith(",status," + ",".join(RAW_CSV_COLUMNS))
    back = read_samples_csv(out)
    for k in ("t", "device_t", "q", "status", "raw"):
        np.testing.assert_array_equal(back[k], stored[k])
    np.testing.assert_array_equal(back["raw"][back["name"] == "humerus"], s["raw"])
    assert np.isnan(back["raw"][back["name"] == "thorax"]).all()
    with pytest.raises(SystemExit) as exc:
        main(["export", "--db", str(tmp_path / "r.db"), "--session", str(sid),
              "--out", str(tmp_path / "s.sto")])
    assert exc.value.code == 0
    assert read_sto(tmp_path / "s.sto").labels == ["humerus_imu", "thorax_imu"]
