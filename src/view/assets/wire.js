// Wire format version 1 (device-protocol/README.md), the packets a phone sends: HELLO,
// PHONE_SAMPLE and KEY. A raw frame is `type:u8, seq:u8, payload…, crc:u16` (every integer and
// float little-endian), the CRC is CRC-16/CCITT-FALSE over type, seq and payload, the frame is
// COBS-encoded and followed by one 0x00. The Rust decoder and this encoder agree byte for byte
// on device-protocol/tests/vectors/phone.json (tests/phone_page.rs runs both).

export const PROTOCOL_VERSION = 1;
export const KIND_PHONE = 2;
export const TYPE = { HELLO: 0x01, PHONE_SAMPLE: 0x11, KEY: 0x20 };

/** CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor). */
export function crc16(bytes) {
  let crc = 0xffff;
  for (const b of bytes) {
    crc ^= b << 8;
    for (let i = 0; i < 8; i++) {
      crc = crc & 0x8000 ? ((crc << 1) ^ 0x1021) & 0xffff : (crc << 1) & 0xffff;
    }
  }
  return crc;
}

/** COBS-encodes `raw` and appends the 0x00 delimiter. */
export function cobs(raw) {
  const out = new Uint8Array(raw.length + Math.ceil(raw.length / 254) + 2);
  let code = 1, codeAt = 0, o = 1;
  for (const b of raw) {
    if (b === 0) {
      out[codeAt] = code; codeAt = o++; code = 1;
    } else {
      out[o++] = b; code++;
      if (code === 0xff) { out[codeAt] = code; codeAt = o++; code = 1; }
    }
  }
  out[codeAt] = code;
  out[o++] = 0;
  return out.slice(0, o);
}

/** One frame on the wire: type, seq and the payload written by `fill(view, offset)`. */
export function frame(type, seq, payloadLength, fill) {
  const raw = new Uint8Array(2 + payloadLength + 2);
  const v = new DataView(raw.buffer);
  raw[0] = type; raw[1] = seq & 0xff;
  fill(v, 2);
  const crc = crc16(raw.subarray(0, 2 + payloadLength));
  v.setUint16(2 + payloadLength, crc, true);
  return cobs(raw);
}

/** A sensor value in counts of `lsb`, rounded and clamped to the i16 rails. */
export function counts(x, lsb) {
  const c = Math.round(x / lsb);
  return Number.isFinite(c) ? Math.max(-32768, Math.min(32767, c)) : 0;
}

/** The device clock: microseconds, wrapping at 2³². */
export function tUs(ms) {
  return Number((BigInt(Math.round(ms * 1000)) % 4294967296n + 4294967296n) % 4294967296n);
}

/** HELLO (32 bytes of payload). */
export function hello(seq, h) {
  return frame(TYPE.HELLO, seq, 32, (v, o) => {
    v.setUint8(o, PROTOCOL_VERSION);
    v.setUint8(o + 1, KIND_PHONE);
    v.setUint32(o + 2, h.deviceId >>> 0, true);
    v.setUint16(o + 6, h.firmware, true);
    v.setUint16(o + 8, h.rateHz, true);
    v.setFloat32(o + 10, h.accScale, true);
    v.setFloat32(o + 14, h.gyroScale, true);
    v.setFloat32(o + 18, h.magScale, true);
    v.setUint32(o + 22, 0, true); // ticks per revolution: no wheel
    v.setUint32(o + 26, 0, true); // wheel circumference
    v.setUint16(o + 30, 1, true); // sensors
  });
}

/** PHONE_SAMPLE (22 bytes): `t_us`, then acc, gyro, mag in counts (i16 × 3 each). */
export function phoneSample(seq, s) {
  return frame(TYPE.PHONE_SAMPLE, seq, 22, (v, o) => {
    v.setUint32(o, s.tUs >>> 0, true);
    [...s.acc, ...s.gyro, ...s.mag].forEach((c, i) => v.setInt16(o + 4 + 2 * i, c, true));
  });
}

/** KEY (5 bytes): `t_us` and the key's ASCII code (Enter is 0x0A). */
export function key(seq, k) {
  return frame(TYPE.KEY, seq, 5, (v, o) => {
    v.setUint32(o, k.tUs >>> 0, true);
    v.setUint8(o + 4, k.key);
  });
}
