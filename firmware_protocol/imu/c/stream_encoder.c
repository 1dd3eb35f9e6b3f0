/* Reference frame encoder for the rig IMU stream protocol 1.1; see stream_encoder.h, ../SPEC.md. */
#include "stream_encoder.h"

uint32_t rig_crc32(const uint8_t *data, size_t n)
{
    uint32_t crc = 0xFFFFFFFFu;
    size_t i;
    int k;
    for (i = 0; i < n; i++) {
        crc ^= data[i];
        for (k = 0; k < 8; k++) {
            crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
        }
    }
    return crc ^ 0xFFFFFFFFu;
}

size_t rig_cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t i;
    size_t o = 1;        /* next output position */
    size_t code_pos = 0; /* where the current block's code byte goes */
    uint8_t code = 1;
    for (i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_pos] = code;
            code_pos = o++;
            code = 1;
            continue;
        }
        out[o++] = in[i];
        code++;
        if (code == 0xFF) {
            out[code_pos] = code;
            if (i + 1 == n) {
                return o; /* canonical: no empty block after a final 0xFF block */
            }
            code_pos = o++;
            code = 1;
        }
    }
    out[code_pos] = code;
    return o;
}

int16_t rig_quat_component(float value)
{
    float scaled = value * 16384.0f;
    if (!(scaled == scaled)) {
        return 0; /* NaN: callers should flag the reading FAULT */
    }
    if (scaled >= 32767.0f) {
        return 32767;
    }
    if (scaled <= -32768.0f) {
        return -32768;
    }
    /* round half away from zero */
    return (int16_t)(scaled >= 0.0f ? (int32_t)(scaled + 0.5f) : -(int32_t)(-scaled + 0.5f));
}

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
    p[2] = (uint8_t)((v >> 16) & 0xFFu);
    p[3] = (uint8_t)(v >> 24);
}

size_t rig_encode_frame(uint8_t type, uint16_t seq, const uint8_t *payload, size_t n,
                        uint8_t *out, size_t cap)
{
    uint8_t body[RIG_MAX_BODY];
    size_t len = 4u + n + 4u;
    size_t i;
    size_t wire;
    if (len > RIG_MAX_BODY || cap < len + 2u + 1u) {
        return 0;
    }
    body[0] = (uint8_t)RIG_PROTOCOL_MAJOR;
    body[1] = type;
    put_u16(body + 2, seq);
    for (i = 0; i < n; i++) {
        body[4 + i] = payload[i];
    }
    put_u32(body + 4 + n, rig_crc32(body, 4u + n));
    wire = rig_cobs_encode(body, len, out);
    out[wire++] = 0x00;
    return wire;
}

size_t rig_encode_sample(uint16_t seq, uint32_t timestamp_us, const rig_reading_t *readings,
                         uint8_t count, uint8_t *out, size_t cap)
{
    return rig_encode_sample_fields(seq, timestamp_us, readings, count, 0u, out, cap);
}

size_t rig_encode_sample_fields(uint16_t seq, uint32_t timestamp_us,
                                const rig_reading_t *readings, uint8_t count, uint8_t fields,
                                uint8_t *out, size_t cap)
{
    /* the larger of 16 plain records (182 bytes) and 8 raw records (238 bytes) */
    uint8_t payload[6u + RIG_MAX_RAW_SENSORS * RIG_RAW_RECORD_SIZE];
    size_t off = 6;
    unsigned i;
    int k;
    int last = -1;
    int raw = (fields & RIG_FIELD_RAW) != 0u;
    size_t record = raw ? RIG_RAW_RECORD_SIZE : RIG_RECORD_SIZE;
    if ((fields & (uint8_t)~RIG_FIELD_RAW) != 0u || count > RIG_MAX_SENSORS
        || (raw && count > RIG_MAX_RAW_SENSORS)) {
        return 0;
    }
    put_u32(payload, timestamp_us);
    payload[4] = count;
    payload[5] = (uint8_t)record;
    for (i = 0; i < count; i++) {
        const rig_reading_t *r = &readings[i];
        if (r->sensor_id >= RIG_MAX_SENSORS || (int)r->sensor_id <= last) {
            return 0;
        }
        last = r->sensor_id;
        payload[off] = r->sensor_id;
        payload[off + 1] = r->calib;
        payload[off + 2] = r->flags;
        for (k = 0; k < 4; k++) {
            put_u16(payload + off + 3 + 2 * k, (uint16_t)r->q[k]);
        }
        if (raw) {
            for (k = 0; k < 9; k++) {
                put_u16(payload + off + RIG_RECORD_SIZE + 2 * k, (uint16_t)r->raw[k]);
            }
        }
        off += record;
    }
    return rig_encode_frame(RIG_SAMPLE, seq, payload, off, out, cap);
}

size_t rig_encode_ack(uint16_t seq, uint16_t command_seq, uint8_t command_type,
                      const uint8_t *data, size_t n, uint8_t *out, size_t cap)
{
    uint8_t payload[RIG_MAX_BODY];
    size_t i;
    if (n > RIG_MAX_BODY - 8u - 3u) {
        return 0;
    }
    put_u16(payload, command_seq);
    payload[2] = command_type;
    for (i = 0; i < n; i++) {
        payload[3 + i] = data[i];
    }
    return rig_encode_frame(RIG_ACK, seq, payload, 3u + n, out, cap);
}

size_t rig_encode_nak(uint16_t seq, uint16_t command_seq, uint8_t command_type, uint8_t error,
                      uint8_t *out, size_t cap)
{
    uint8_t payload[4];
    put_u16(payload, command_seq);
    payload[2] = command_type;
    payload[3] = error;
    return rig_encode_frame(RIG_NAK, seq, payload, sizeof payload, out, cap);
}

size_t rig_encode_command(uint16_t seq, uint8_t command_type, uint16_t arg, int arg_len,
                          uint8_t *out, size_t cap)
{
    uint8_t payload[2];
    if (arg_len < 0 || arg_len > 2 || (arg_len == 1 && arg > 0xFFu)) {
        return 0;
    }
    put_u16(payload, arg);
    return rig_encode_frame(command_type, seq, payload, (size_t)arg_len, out, cap);
}
