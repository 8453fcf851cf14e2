//! CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final xor.
//!
//! Check value (the CRC of the ASCII bytes `123456789`) is `0x29B1`.
//!
//! ```
//! assert_eq!(device_protocol::crc16(b"123456789"), 0x29B1);
//! ```

/// Polynomial of CRC-16/CCITT-FALSE.
pub const POLY: u16 = 0x1021;
/// Initial register value of CRC-16/CCITT-FALSE.
pub const INIT: u16 = 0xFFFF;

const fn make_table() -> [[u16; 256]; 2] {
    let mut t = [[0u16; 256]; 2];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut b = 0;
        while b < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ POLY
            } else {
                crc << 1
            };
            b += 1;
        }
        t[0][i] = crc;
        i += 1;
    }
    // Second table: the effect of a byte followed by one zero byte (slicing-by-2).
    let mut i = 0;
    while i < 256 {
        let c = t[0][i];
        t[1][i] = (c << 8) ^ t[0][(c >> 8) as usize];
        i += 1;
    }
    t
}

static TABLE: [[u16; 256]; 2] = make_table();

/// Continues a CRC-16/CCITT-FALSE computation from register value `crc` over `data`.
#[inline]
pub fn crc16_update(mut crc: u16, data: &[u8]) -> u16 {
    let mut pairs = data.chunks_exact(2);
    for p in &mut pairs {
        let x = crc ^ u16::from_be_bytes([p[0], p[1]]);
        crc = TABLE[1][(x >> 8) as usize] ^ TABLE[0][(x & 0xFF) as usize];
    }
    for &b in pairs.remainder() {
        crc = (crc << 8) ^ TABLE[0][((crc >> 8) as u8 ^ b) as usize];
    }
    crc
}

/// CRC-16/CCITT-FALSE of `data`.
#[inline]
pub fn crc16(data: &[u8]) -> u16 {
    crc16_update(INIT, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bitwise(data: &[u8]) -> u16 {
        let mut crc = INIT;
        for &b in data {
            crc ^= (b as u16) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ POLY
                } else {
                    crc << 1
                };
            }
        }
        crc
    }

    #[test]
    fn check_value() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
        assert_eq!(crc16(b""), 0xFFFF);
    }

    #[test]
    fn table_matches_bitwise_definition() {
        let data: Vec<u8> = (0..=255u8).chain((0..97).map(|i| (i * 37) as u8)).collect();
        for len in 0..data.len() {
            assert_eq!(crc16(&data[..len]), bitwise(&data[..len]), "len {len}");
        }
    }
}
