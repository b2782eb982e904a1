//! Read Device Identification (function 43, MEI type 14; Modbus
//! application protocol 1.1b3, 6.21): the three basic objects, by stream
//! (codes 1 to 3) or one at a time (code 4), conformity level 81H.
//!
//! - 00H VendorName [`VENDOR`], 01H ProductCode [`PRODUCT`];
//! - 02H MajorMinorRevision: the firmware's version, then, once the
//!   gateway has the controller's 201H reply (main CPU application; asked
//!   each time the line comes up), `; controller VVVV model MM unit UU
//!   YYYY-MM-DD` (the version number and codes in hex, as 201H gives
//!   them, the build date in decimal). Before that, while the line is
//!   down, from a controller that refuses 201H, or under a command policy
//!   that does not allow it: the firmware's version alone.
//!
//! A stream request for the regular or extended objects is answered with
//! the basic ones (the standard: a server answers at its conformity
//! level); a stream from an object ID it does not have starts at 00H.
//! Refused: another MEI type, 01 (as an unknown function); a request
//! that is not 4 bytes or a code outside 1 to 4, 03; code 4 for an object
//! other than 00H to 02H, 02.

use iai_protocol_b::message::VersionResponse;

/// Function 43 (2BH), the encapsulated interface.
pub const FUNCTION: u8 = 0x2B;
/// MEI type 14 (0EH): Read Device Identification.
pub const MEI_DEVICE_ID: u8 = 0x0E;
/// Object 00H, VendorName.
pub const VENDOR: &str = "iai-protocol-b";
/// Object 01H, ProductCode.
pub const PRODUCT: &str = "protocol-B Modbus gateway";
/// The firmware's version (the start of object 02H).
pub const FIRMWARE: &str = env!("CARGO_PKG_VERSION");
/// Basic identification, stream and individual access.
pub const CONFORMITY: u8 = 0x81;
/// The last basic object (MajorMinorRevision).
const LAST_OBJECT: u8 = 2;

/// Object 02H's text: the firmware's version and, when known, the
/// controller's.
pub type Revision = heapless::Vec<u8, 64>;

/// Object 02H for `version` (the controller's 201H reply, if any).
pub fn revision(version: Option<&VersionResponse>) -> Revision {
    let mut r = Revision::new();
    let _ = r.extend_from_slice(FIRMWARE.as_bytes());
    if let Some(v) = version {
        let mut put = |s: &[u8]| {
            let _ = r.extend_from_slice(s);
        };
        put(b"; controller ");
        put(&hex(u32::from(v.version_number), 4));
        put(b" model ");
        put(&hex(u32::from(v.model_code), 2));
        put(b" unit ");
        put(&hex(u32::from(v.unit_code), 2));
        put(b" ");
        put(&dec(u32::from(v.year), 4));
        put(b"-");
        put(&dec(u32::from(v.month), 2));
        put(b"-");
        put(&dec(u32::from(v.day), 2));
    }
    r
}

/// `v` as `n` upper-case hex digits (n ≤ 8).
fn hex(v: u32, n: usize) -> heapless::Vec<u8, 8> {
    const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
    (0..n.min(8))
        .rev()
        .map(|i| {
            DIGITS
                .get((v >> (4 * i) & 0xF) as usize)
                .copied()
                .unwrap_or(b'?')
        })
        .collect()
}

/// `v` as `n` decimal digits (the low ones, n ≤ 8).
fn dec(v: u32, n: usize) -> heapless::Vec<u8, 8> {
    (0..n.min(8) as u32)
        .rev()
        .map(|i| b'0' + (v / 10u32.pow(i) % 10) as u8)
        .collect()
}

/// The answer to the request PDU `pdu` (function code first) appended to
/// `out`: its PDU, or `Err` with the exception code (nothing appended).
pub fn answer<const N: usize>(
    pdu: &[u8],
    version: Option<&VersionResponse>,
    out: &mut heapless::Vec<u8, N>,
) -> Result<(), u8> {
    let [FUNCTION, mei, code, object] = *pdu else {
        return Err(match pdu.get(1) {
            Some(&MEI_DEVICE_ID) => 3,
            _ => 1,
        });
    };
    if mei != MEI_DEVICE_ID {
        return Err(1);
    }
    let objects = match code {
        1..=3 if object <= LAST_OBJECT => object..=LAST_OBJECT,
        1..=3 => 0..=LAST_OBJECT,
        4 if object <= LAST_OBJECT => object..=object,
        4 => return Err(2),
        _ => return Err(3),
    };
    let revision = revision(version);
    let start = out.len();
    let count = objects.clone().count() as u8;
    // No more follows, next object 0.
    let head = [FUNCTION, MEI_DEVICE_ID, code, CONFORMITY, 0, 0, count];
    let mut ok = out.extend_from_slice(&head).is_ok();
    for id in objects {
        let text = match id {
            0 => VENDOR.as_bytes(),
            1 => PRODUCT.as_bytes(),
            _ => &revision,
        };
        ok &= out.push(id).is_ok()
            && out.push(text.len() as u8).is_ok()
            && out.extend_from_slice(text).is_ok();
    }
    if !ok {
        out.truncate(start);
        return Err(4);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn ask(pdu: &[u8], version: Option<&VersionResponse>) -> Result<heapless::Vec<u8, 253>, u8> {
        let mut out = heapless::Vec::new();
        answer(pdu, version, &mut out).map(|()| out)
    }

    #[test]
    fn the_basic_objects_by_stream_and_one_at_a_time() {
        let all = ask(&[0x2B, 0x0E, 1, 0], None).unwrap();
        let mut want = std::vec![0x2B, 0x0E, 1, 0x81, 0, 0, 3];
        for (id, text) in [(0u8, VENDOR), (1, PRODUCT), (2, FIRMWARE)] {
            want.extend([id, text.len() as u8]);
            want.extend(text.as_bytes());
        }
        assert_eq!(all[..], want[..]);
        // Regular and extended: the basic objects, at the conformity level.
        assert_eq!(ask(&[0x2B, 0x0E, 3, 0], None).unwrap()[7..], want[7..]);
        // A stream from object 1; from an object we do not have: from 0.
        assert_eq!(ask(&[0x2B, 0x0E, 1, 1], None).unwrap()[6], 2);
        assert_eq!(ask(&[0x2B, 0x0E, 2, 0x80], None).unwrap()[6], 3);
        // One object.
        let one = ask(&[0x2B, 0x0E, 4, 1], None).unwrap();
        assert_eq!(one[6..9], [1, 1, PRODUCT.len() as u8]);
        assert_eq!(one[9..], *PRODUCT.as_bytes());
    }

    #[test]
    fn the_revision_says_the_controllers_201h_version_once_known() {
        let v = VersionResponse {
            model_code: 0x4C,
            unit_code: 0x01,
            version_number: 0x0107,
            year: 2024,
            month: 3,
            day: 5,
            ..VersionResponse::default()
        };
        let text = revision(Some(&v));
        let want = std::format!("{FIRMWARE}; controller 0107 model 4C unit 01 2024-03-05");
        assert_eq!(text[..], *want.as_bytes());
        let one = ask(&[0x2B, 0x0E, 4, 2], Some(&v)).unwrap();
        assert_eq!(one[9..], *want.as_bytes());
    }

    #[test]
    fn misuses_by_exception_code() {
        // Another MEI type (0DH, CANopen): as an unknown function.
        assert_eq!(ask(&[0x2B, 0x0D, 1, 0], None), Err(1));
        // A code outside 1..=4, a request of the wrong length.
        assert_eq!(ask(&[0x2B, 0x0E, 5, 0], None), Err(3));
        assert_eq!(ask(&[0x2B, 0x0E, 1], None), Err(3));
        assert_eq!(ask(&[0x2B, 0x0E, 1, 0, 0], None), Err(3));
        // One object we do not have.
        assert_eq!(ask(&[0x2B, 0x0E, 4, 3], None), Err(2));
    }
}
