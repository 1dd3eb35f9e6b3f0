/*
 * Reference frame encoder for the rig IMU stream protocol, version 1.1 (see ../SPEC.md).
 *
 * Portable C99, no allocation, no I/O, no floating point except in rig_quat_component().
 * Every encoder writes a complete wire frame -- COBS(body) followed by the 0x00 delimiter --
 * into a caller buffer and returns its length, or 0 if the buffer is too small or an argument
 * is out of range. RIG_WIRE_MAX bytes always suffice.
 */
#ifndef RIG_STREAM_ENCODER_H
#define RIG_STREAM_ENCODER_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RIG_PROTOCOL_MAJOR 1u
#define RIG_PROTOCOL_MINOR 1u
#define RIG_MAX_BODY 256u                 /* header + payload + CRC, before COBS */
#define RIG_WIRE_MAX (RIG_MAX_BODY + 2u + 1u) /* COBS overhead + delimiter */
#define RIG_MAX_SENSORS 16u
#define RIG_RECORD_SIZE 11u                /* a record without optional fields (1.0) */
#define RIG_RAW_RECORD_SIZE 29u            /* with the RAW fields (1.1) */
#define RIG_MAX_RAW_SENSORS 8u             /* 6 + 8 * 29 payload bytes fit a frame, 9 do not */

enum rig_frame_type {
    RIG_SAMPLE = 0x01,
    RIG_ACK = 0x02,
    RIG_NAK = 0x03,
    RIG_CMD_IDENTIFY = 0x80,
    RIG_CMD_START = 0x81,
    RIG_CMD_STOP = 0x82,
    RIG_CMD_SET_RATE = 0x83,
    RIG_CMD_SET_SENSORS = 0x84,
    RIG_CMD_SET_FIELDS = 0x85 /* 1.1: u8 field mask */
};

enum rig_error {
    RIG_ERR_UNKNOWN_COMMAND = 0x01,
    RIG_ERR_BAD_LENGTH = 0x02,
    RIG_ERR_BAD_ARGUMENT = 0x03,
    RIG_ERR_BAD_STATE = 0x04,
    RIG_ERR_UNSUPPORTED_VERSION = 0x05,
    RIG_ERR_SENSOR_FAULT = 0x06
};

#define RIG_FLAG_STALE 0x01u
#define RIG_FLAG_FAULT 0x02u

#define RIG_FIELD_RAW 0x01u /* SET_FIELDS bit 0: raw acc/gyr/mag in every record */

/* One sensor record of a SAMPLE. q is scalar first (w, x, y, z), 1 LSB = 2^-14. raw is sent
 * only with RIG_FIELD_RAW: acc x,y,z (100 LSB = 1 m/s^2), gyr x,y,z (16 LSB = 1 deg/s), mag
 * x,y,z (16 LSB = 1 uT), sensor frame -- the BNO055's ACC_DATA, GYR_DATA and MAG_DATA register
 * values (UNIT_SEL m/s^2 and dps) copied unchanged; zeros for a FAULT reading. */
typedef struct {
    uint8_t sensor_id; /* 0..15, strictly increasing within a sample */
    uint8_t calib;     /* BNO055 CALIB_STAT byte */
    uint8_t flags;     /* RIG_FLAG_* */
    int16_t q[4];
    int16_t raw[9];
} rig_reading_t;

/* CRC-32/ISO-HDLC (poly 0x04C11DB7 reflected, init and xorout 0xFFFFFFFF). */
uint32_t rig_crc32(const uint8_t *data, size_t n);

/* Canonical COBS of n bytes into out (room for n + 1 + n/254); returns the length. */
size_t rig_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);

/* Round and saturate one quaternion component to int16 at 2^-14 per LSB. */
int16_t rig_quat_component(float value);

/* Any frame: header (version, type, seq), payload, CRC; COBS; delimiter. */
size_t rig_encode_frame(uint8_t type, uint16_t seq, const uint8_t *payload, size_t n,
                        uint8_t *out, size_t cap);

/* A SAMPLE with 1.0 records (record_size 11): rig_encode_sample_fields with fields 0. */
size_t rig_encode_sample(uint16_t seq, uint32_t timestamp_us, const rig_reading_t *readings,
                         uint8_t count, uint8_t *out, size_t cap);

/* A SAMPLE with the optional fields of the SET_FIELDS mask: 0 (record_size 11) or RIG_FIELD_RAW
 * (record_size 29, at most RIG_MAX_RAW_SENSORS readings). Other bits: returns 0. */
size_t rig_encode_sample_fields(uint16_t seq, uint32_t timestamp_us,
                                const rig_reading_t *readings, uint8_t count, uint8_t fields,
                                uint8_t *out, size_t cap);

size_t rig_encode_ack(uint16_t seq, uint16_t command_seq, uint8_t command_type,
                      const uint8_t *data, size_t n, uint8_t *out, size_t cap);

size_t rig_encode_nak(uint16_t seq, uint16_t command_seq, uint8_t command_type, uint8_t error,
                      uint8_t *out, size_t cap);

/* Host side: a command with no argument (arg_len 0), a u8 (arg_len 1: SET_FIELDS) or a u16
 * argument (arg_len 2). */
size_t rig_encode_command(uint16_t seq, uint8_t command_type, uint16_t arg, int arg_len,
                          uint8_t *out, size_t cap);

#ifdef __cplusplus
}
#endif

#endif /* RIG_STREAM_ENCODER_H */
