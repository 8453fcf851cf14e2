//! Consistent Overhead Byte Stuffing: removes every `0x00` from a frame so that `0x00` can
//! delimit frames on the wire.
//!
//! ```
//! use device_protocol::cobs;
//! let mut enc = Vec::new();
//! cobs::encode(&[0x11, 0x00, 0x22], &mut enc);
//! assert_eq!(enc, [0x02, 0x11, 0x02, 0x22]);
//! let mut dec = [0u8; 8];
//! let n = cobs::decode(&enc, &mut dec).unwrap();
//! assert_eq!(&dec[..n], &[0x11, 0x00, 0x22]);
//! ```

/// The encoded form of `src` is malformed: a code byte is zero or announces more bytes than
/// the frame holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CobsError {
    /// Offset in the encoded frame of the offending code byte.
    pub offset: usize,
}

/// Largest encoded length of a `raw_len`-byte frame (without the delimiter).
pub const fn max_encoded_len(raw_len: usize) -> usize {
    raw_len + raw_len / 254 + 1
}

/// Appends the COBS encoding of `src` to `out` (without the `0x00` delimiter).
pub fn encode(src: &[u8], out: &mut Vec<u8>) {
    out.reserve(max_encoded_len(src.len()));
    let mut code_at = out.len();
    out.push(0);
    let mut code: u8 = 1;
    for &b in src {
        if b == 0 {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        } else {
            out.push(b);
            code += 1;
            if code == 0xFF {
                out[code_at] = code;
                code_at = out.len();
                out.push(0);
                code = 1;
            }
        }
    }
    out[code_at] = code;
}

/// Decodes one COBS frame `src` (without its delimiter) into `dst` and returns the decoded
/// length. `dst` must hold at least `src.len()` bytes; the decoded frame is always shorter.
#[inline]
pub fn decode(src: &[u8], dst: &mut [u8]) -> Result<usize, CobsError> {
    debug_assert!(dst.len() >= src.len());
    let mut i = 0;
    let mut o = 0;
    while i < src.len() {
        let code = src[i] as usize;
        if code == 0 {
            return Err(CobsError { offset: i });
        }
        let start = i + 1;
        let end = i + code;
        if end > src.len() {
            return Err(CobsError { offset: i });
        }
        let run = &src[start..end];
        if run.contains(&0) {
            return Err(CobsError { offset: i });
        }
        dst[o..o + run.len()].copy_from_slice(run);
        o += run.len();
        i = end;
        if code < 0xFF && i < src.len() {
            dst[o] = 0;
            o += 1;
        }
    }
    Ok(o)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(raw: &[u8]) {
        let mut enc = Vec::new();
        encode(raw, &mut enc);
        assert!(!enc.contains(&0), "encoded frame contains a zero: {enc:?}");
        assert!(enc.len() <= max_encoded_len(raw.len()));
        let mut dec = vec![0u8; enc.len()];
        let n = decode(&enc, &mut dec).unwrap();
        assert_eq!(&dec[..n], raw);
    }

    #[test]
    fn known_vectors() {
        // Vectors from the COBS paper / Wikipedia.
        let cases: &[(&[u8], &[u8])] = &[
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x22, 0x33, 0x44], &[0x05, 0x11, 0x22, 0x33, 0x44]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, want) in cases {
            let mut enc = Vec::new();
            encode(raw, &mut enc);
            assert_eq!(&enc[..], *want);
            roundtrip(raw);
        }
    }

    #[test]
    fn long_runs() {
        for len in [0usize, 1, 253, 254, 255, 256, 508, 509, 600] {
            let raw: Vec<u8> = (0..len).map(|i| (i % 255 + 1) as u8).collect();
            roundtrip(&raw);
            let mut with_zeros = raw.clone();
            with_zeros.iter_mut().step_by(97).for_each(|b| *b = 0);
            roundtrip(&with_zeros);
        }
    }

    #[test]
    fn malformed_is_an_error() {
        let mut dst = [0u8; 16];
        assert_eq!(
            decode(&[0x05, 0x11], &mut dst),
            Err(CobsError { offset: 0 })
        );
        assert_eq!(
            decode(&[0x02, 0x11, 0x04, 0x22], &mut dst),
            Err(CobsError { offset: 2 })
        );
        assert_eq!(decode(&[0x00], &mut dst), Err(CobsError { offset: 0 }));
    }
}
