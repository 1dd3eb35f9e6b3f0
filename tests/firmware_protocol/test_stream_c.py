"""The C99 reference encoder (firmware_protocol/imu/c) against SPEC.md and the Python decoder.

Compiled with gcc (``-std=c99 -Wall -Wextra -pedantic -Werror``); skipped when gcc is absent.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from firmware_protocol.imu import stream as S

C_DIR = Path(S.__file__).with_name("c")
SPEC = Path(S.__file__).with_name("SPEC.md")

DRIVER = r"""
#include <stdio.h>
#include <string.h>
#include "stream_encoder.h"

static void hex(const char *name, const uint8_t *p, size_t n)
{
    size_t i;
    printf("%s", name);
    for (i = 0; i < n; i++) printf(" %02x", p[i]);
    printf("\n");
}

int main(void)
{
    uint8_t out[RIG_WIRE_MAX];
    size_t n;
    char cmd[8];
    int i;
    static const uint8_t ident[20] = {1, 0, 0x00, 0x01, 0x01, 0x00, 0x57, 0x51, 16, 0,
                                      0x0f, 0, 0x05, 0, 200, 0, 10, 0, 0x90, 0x01};
    rig_reading_t r[16];

    printf("crc %08lx\n", (unsigned long)rig_crc32((const uint8_t *)"123456789", 9));
    n = rig_encode_command(0, RIG_CMD_IDENTIFY, 0, 0, out, sizeof out); hex("identify", out, n);
    n = rig_encode_command(1, RIG_CMD_START, 0, 0, out, sizeof out); hex("start", out, n);
    n = rig_encode_command(0x0102, RIG_CMD_STOP, 0, 0, out, sizeof out); hex("stop", out, n);
    n = rig_encode_command(2, RIG_CMD_SET_RATE, 200, 2, out, sizeof out); hex("set_rate", out, n);
    n = rig_encode_command(3, RIG_CMD_SET_SENSORS, 5, 2, out, sizeof out);
    hex("set_sensors", out, n);
    n = rig_encode_ack(0x10, 1, RIG_CMD_START, NULL, 0, out, sizeof out); hex("ack_start", out, n);
    n = rig_encode_nak(0x11, 2, RIG_CMD_SET_RATE, RIG_ERR_BAD_ARGUMENT, out, sizeof out);
    hex("nak_rate", out, n);
    n = rig_encode_ack(0x12, 0, RIG_CMD_IDENTIFY, ident, sizeof ident, out, sizeof out);
    hex("ack_identify", out, n);
    r[0].sensor_id = 0; r[0].calib = 0xff; r[0].flags = 0;
    r[0].q[0] = rig_quat_component(1.0f); r[0].q[1] = 0; r[0].q[2] = 0; r[0].q[3] = 0;
    r[1].sensor_id = 2; r[1].calib = 0x3f; r[1].flags = RIG_FLAG_STALE;
    r[1].q[0] = rig_quat_component(0.5f); r[1].q[1] = rig_quat_component(-0.5f);
    r[1].q[2] = rig_quat_component(0.5f); r[1].q[3] = rig_quat_component(-0.5f);
    n = rig_encode_sample(0x1234, 0x89ABCDEFu, r, 2, out, sizeof out); hex("sample", out, n);
    r[0].sensor_id = 1; r[0].calib = 0xc0; r[0].flags = 0;
    r[0].q[0] = rig_quat_component(0.7071f); r[0].q[1] = 0;
    r[0].q[2] = rig_quat_component(0.7071f); r[0].q[3] = 0;
    n = rig_encode_sample(0xFFFF, 0xFFFFFF00u, r, 1, out, sizeof out); hex("sample_wrap", out, n);
    n = rig_encode_sample(0, 0, r, 0, out, sizeof out); hex("sample_empty", out, n);
    r[0].sensor_id = 3; r[0].calib = 0; r[0].flags = RIG_FLAG_FAULT;
    memset(r[0].q, 0, sizeof r[0].q);
    n = rig_encode_sample(5, 1000, r, 1, out, sizeof out); hex("sample_fault", out, n);
    n = rig_encode_command(4, RIG_CMD_SET_FIELDS, RIG_FIELD_RAW, 1, out, sizeof out);
    hex("set_fields", out, n);
    n = rig_encode_nak(0x13, 4, RIG_CMD_SET_FIELDS, RIG_ERR_UNKNOWN_COMMAND, out, sizeof out);
    hex("nak_fields", out, n);
    memset(r, 0, sizeof r);
    r[0].sensor_id = 0; r[0].calib = 0xff; r[0].flags = 0; r[0].q[0] = rig_quat_component(1.0f);
    r[0].raw[0] = 12; r[0].raw[1] = -50; r[0].raw[2] = 981;    /* ACC_DATA, 100 LSB/(m/s^2) */
    r[0].raw[3] = 16; r[0].raw[4] = -32; r[0].raw[5] = 0;      /* GYR_DATA, 16 LSB/(deg/s) */
    r[0].raw[6] = 320; r[0].raw[7] = -88; r[0].raw[8] = -688;  /* MAG_DATA, 16 LSB/uT */
    r[1].sensor_id = 1; r[1].calib = 0; r[1].flags = RIG_FLAG_FAULT;
    n = rig_encode_sample_fields(0x0100, 2000000u, r, 2, RIG_FIELD_RAW, out, sizeof out);
    hex("sample_raw", out, n);
    /* refused: 9 raw readings, a reserved field bit, a u8 argument above 255 */
    for (i = 0; i < 9; i++) r[i].sensor_id = (uint8_t)i;
    printf("refused %u %u %u\n",
           (unsigned)rig_encode_sample_fields(0, 0, r, 9, RIG_FIELD_RAW, out, sizeof out),
           (unsigned)rig_encode_sample_fields(0, 0, r, 1, 0x02, out, sizeof out),
           (unsigned)rig_encode_command(0, RIG_CMD_SET_FIELDS, 256, 1, out, sizeof out));
    fflush(stdout);

    /* random samples from stdin: S|R seq ts count (id calib flags w x y z [9 raw]) * count */
    while (scanf("%7s", cmd) == 1) {
        unsigned seq, count;
        unsigned long ts;
        int with_raw = strcmp(cmd, "R") == 0;
        if (!with_raw && strcmp(cmd, "S") != 0) return 2;
        if (scanf("%u %lu %u", &seq, &ts, &count) != 3 || count > 16) return 3;
        for (i = 0; i < (int)count; i++) {
            unsigned id, calib, flags;
            int w, x, y, z, k, v;
            if (scanf("%u %u %u %d %d %d %d", &id, &calib, &flags, &w, &x, &y, &z) != 7)
                return 4;
            r[i].sensor_id = (uint8_t)id; r[i].calib = (uint8_t)calib;
            r[i].flags = (uint8_t)flags;
            r[i].q[0] = (int16_t)w; r[i].q[1] = (int16_t)x;
            r[i].q[2] = (int16_t)y; r[i].q[3] = (int16_t)z;
            for (k = 0; with_raw && k < 9; k++) {
                if (scanf("%d", &v) != 1) return 5;
                r[i].raw[k] = (int16_t)v;
            }
        }
        n = rig_encode_sample_fields((uint16_t)seq, (uint32_t)ts, r, (uint8_t)count,
                                     with_raw ? RIG_FIELD_RAW : 0u, out, sizeof out);
        hex(cmd, out, n);
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def encoder(tmp_path_factory) -> Path:
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc not installed")
    tmp = tmp_path_factory.mktemp("c_encoder")
    (tmp / "driver.c").write_text(DRIVER)
    exe = tmp / "driver"
    subprocess.run(
        [gcc, "-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", f"-I{C_DIR}",
         str(C_DIR / "stream_encoder.c"), str(tmp / "driver.c"), "-o", str(exe)],
        check=True, capture_output=True, text=True,
    )
    return exe


def _spec_wires() -> dict[str, str]:
    text = SPEC.read_text(encoding="utf-8")
    out = {}
    for block in re.findall(r"```vector\n(.*?)```", text, flags=re.S):
        fields = dict(re.findall(r"^(vector|wire):\s*(.*)$", block, flags=re.M))
        out[fields["vector"].split()[0]] = fields["wire"].strip()
    return out


def test_c_encoder_reproduces_spec_vectors(encoder):
    proc = subprocess.run([str(encoder)], input="", capture_output=True, text=True, check=True,
                          timeout=10)
    lines = dict(line.split(" ", 1) for line in proc.stdout.splitlines())
    assert lines.pop("crc") == "cbf43926"
    assert lines.pop("refused") == "0 0 0"
    assert lines == _spec_wires()


_RAW_UNIT = np.array([1 / S.ACC_SCALE] * 3 + [np.pi / (180 * S.GYR_SCALE)] * 3
                     + [1 / S.MAG_SCALE] * 3)


def test_c_encoder_random_samples_decode_in_python(encoder):
    rng = np.random.default_rng(7)
    requests, expected = [], []
    for k in range(300):
        seq = int(rng.integers(0, 1 << 16))
        ts = int(rng.integers(0, 1 << 32))
        with_raw = k % 2 == 1
        most = S.MAX_RAW_SENSORS if with_raw else 16
        ids = sorted(rng.choice(16, size=int(rng.integers(0, most + 1)), replace=False).tolist())
        recs = []
        for sid in ids:
            q = rng.integers(-32768, 32768, size=4).tolist()
            raw = rng.integers(-32768, 32768, size=9).tolist() if with_raw else []
            if k % 3 == 0:
                q, raw = [0] * 4, [0] * len(raw)  # many zero bytes: COBS edge cases
            recs.append((sid, int(rng.integers(0, 256)), int(rng.integers(0, 4)), q, raw))
        requests.append(f"{'R' if with_raw else 'S'} {seq} {ts} {len(recs)} " + " ".join(
            " ".join(map(str, (s, c, f, *q, *raw))) for s, c, f, q, raw in recs))
        expected.append(S.Sample(seq, ts, tuple(
            S.SensorReading(s, c, f, tuple(v / 16384 for v in q),
                            tuple((np.array(raw) * _RAW_UNIT).tolist()) if with_raw else None)
            for s, c, f, q, raw in recs)))
    proc = subprocess.run([str(encoder)], input="\n".join(requests) + "\n", capture_output=True,
                          text=True, check=True, timeout=10)
    wires = [bytes.fromhex(line[2:]) for line in proc.stdout.splitlines()
             if line[:2] in ("S ", "R ")]
    assert len(wires) == len(expected)
    dec = S.StreamDecoder(track_sequence=False)
    dec.feed(b"".join(wires))
    assert dec.drain() == expected
    assert dec.errors == 0
