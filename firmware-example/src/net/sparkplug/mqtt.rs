//! The MQTT 3.1.1 packets an edge node needs (OASIS MQTT 3.1.1, 2.2 and
//! 3): CONNECT with a Will and credentials, PUBLISH at QoS 0, PUBACK,
//! SUBSCRIBE, PINGREQ and DISCONNECT out; CONNACK, PUBLISH (QoS 0 to 2),
//! PUBACK, SUBACK and PINGRESP in. Sans-IO: packets are written into a
//! caller's buffer ([`Writer`]) and cut from a byte stream by
//! [`frame_len`], then read by [`parse`]; nothing here blocks, allocates
//! or panics, and a malformed packet is a [`Malformed`] error.

/// Longest remaining length the standard allows (four length bytes).
pub const MAX_REMAINING: usize = 268_435_455;
/// Most bytes a fixed header takes (type and four length bytes).
pub const MAX_HEADER: usize = 5;

/// The packet is not MQTT 3.1.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Malformed;

/// A packet from the broker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Packet<'a> {
    /// CONNACK with its return code (0: accepted).
    ConnAck {
        /// 0 accepted; 1 protocol, 2 client ID, 3 server unavailable,
        /// 4 bad user name or password, 5 not authorised.
        code: u8,
    },
    /// PUBLISH.
    Publish {
        /// Topic name.
        topic: &'a str,
        /// QoS 0, 1 or 2.
        qos: u8,
        /// Packet identifier (QoS 1 and 2).
        id: Option<u16>,
        /// Application message.
        payload: &'a [u8],
    },
    /// PUBACK.
    PubAck {
        /// Packet identifier.
        id: u16,
    },
    /// SUBACK.
    SubAck {
        /// Packet identifier.
        id: u16,
        /// Granted QoS per topic filter (0x80: refused).
        codes: &'a [u8],
    },
    /// PINGRESP.
    PingResp,
    /// Another packet type a broker may send (PUBREC, PUBREL, PUBCOMP,
    /// UNSUBACK): taken and ignored.
    Other(u8),
}

/// The whole length (fixed header included) of the packet at the head of
/// `buf`: `Ok(None)` while its header is incomplete.
pub fn frame_len(buf: &[u8]) -> Result<Option<usize>, Malformed> {
    let mut remaining = 0usize;
    for i in 0..4 {
        let Some(&b) = buf.get(1 + i) else {
            return Ok(None);
        };
        remaining |= usize::from(b & 0x7F) << (7 * i);
        if b & 0x80 == 0 {
            return Ok(Some(2 + i + remaining));
        }
    }
    Err(Malformed)
}

/// Reads one whole packet (as [`frame_len`] cut it).
pub fn parse(packet: &[u8]) -> Result<Packet<'_>, Malformed> {
    let total = frame_len(packet)?.ok_or(Malformed)?;
    if total != packet.len() {
        return Err(Malformed);
    }
    let first = *packet.first().ok_or(Malformed)?;
    let header = packet
        .iter()
        .skip(1)
        .take(4)
        .position(|b| b & 0x80 == 0)
        .ok_or(Malformed)?;
    let body = packet.get(2 + header..).ok_or(Malformed)?;
    let u16_at = |at: usize| -> Result<u16, Malformed> {
        match body.get(at..at + 2) {
            Some(&[hi, lo]) => Ok(u16::from_be_bytes([hi, lo])),
            _ => Err(Malformed),
        }
    };
    match first >> 4 {
        2 => match body {
            [flags, code] if *flags & !1 == 0 => Ok(Packet::ConnAck { code: *code }),
            _ => Err(Malformed),
        },
        3 => {
            let qos = (first >> 1) & 3;
            if qos == 3 {
                return Err(Malformed);
            }
            let len = usize::from(u16_at(0)?);
            let topic = body.get(2..2 + len).ok_or(Malformed)?;
            let topic = core::str::from_utf8(topic).map_err(|_| Malformed)?;
            let (id, rest) = if qos > 0 {
                (Some(u16_at(2 + len)?), 4 + len)
            } else {
                (None, 2 + len)
            };
            let payload = body.get(rest..).ok_or(Malformed)?;
            Ok(Packet::Publish {
                topic,
                qos,
                id,
                payload,
            })
        }
        4 if body.len() == 2 => Ok(Packet::PubAck { id: u16_at(0)? }),
        9 => Ok(Packet::SubAck {
            id: u16_at(0)?,
            codes: body.get(2..).ok_or(Malformed)?,
        }),
        13 if body.is_empty() => Ok(Packet::PingResp),
        t @ (5 | 6 | 7 | 11) => Ok(Packet::Other(t)),
        _ => Err(Malformed),
    }
}

/// Bytes written into a caller's buffer; writing past its end sets
/// [`Writer::overflowed`] and writes nothing more.
pub struct Writer<'a> {
    buf: &'a mut [u8],
    len: usize,
    overflow: bool,
}

impl<'a> Writer<'a> {
    /// Writes into `buf` from its start.
    pub fn new(buf: &'a mut [u8]) -> Self {
        Writer {
            buf,
            len: 0,
            overflow: false,
        }
    }

    /// Bytes written.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Nothing written.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// A write did not fit.
    pub fn overflowed(&self) -> bool {
        self.overflow
    }

    /// Marks the packet as not fitting.
    pub fn fail(&mut self) {
        self.overflow = true;
    }

    /// What was written.
    pub fn written(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }

    /// Forgets what was written from `at` on.
    pub fn truncate(&mut self, at: usize) {
        self.len = self.len.min(at);
    }

    /// Appends `bytes`.
    pub fn put(&mut self, bytes: &[u8]) {
        match self.buf.get_mut(self.len..self.len + bytes.len()) {
            Some(dst) if !self.overflow => {
                dst.copy_from_slice(bytes);
                self.len += bytes.len();
            }
            _ => self.overflow = true,
        }
    }

    /// Appends one byte.
    pub fn byte(&mut self, b: u8) {
        self.put(&[b]);
    }

    /// Appends a big-endian 16-bit number.
    pub fn u16(&mut self, v: u16) {
        self.put(&v.to_be_bytes());
    }

    /// Appends an MQTT string or binary field (length first).
    pub fn field(&mut self, bytes: &[u8]) {
        match u16::try_from(bytes.len()) {
            Ok(n) => {
                self.u16(n);
                self.put(bytes);
            }
            Err(_) => self.overflow = true,
        }
    }

    /// Moves what was written from `from` on `by` bytes towards the start
    /// (closing a gap left for a length).
    pub fn close_gap(&mut self, from: usize, by: usize) {
        if by == 0 || self.overflow {
            return;
        }
        if by > from || from > self.len {
            self.overflow = true;
            return;
        }
        shift_down(self.buf, from..self.len, by);
        self.len -= by;
    }

    /// Writes `bytes` at `at` over what was written there.
    pub fn patch(&mut self, at: usize, bytes: &[u8]) {
        match self.buf.get_mut(at..at + bytes.len()) {
            Some(dst) if at + bytes.len() <= self.len => dst.copy_from_slice(bytes),
            _ => self.overflow = true,
        }
    }
}

/// Moves the bytes of `buf` in `range` `by` places towards the start, one
/// at a time (`copy_within` would keep a bounds panic in the image).
pub fn shift_down(buf: &mut [u8], range: core::ops::Range<usize>, by: usize) {
    for i in range {
        let b = buf.get(i).copied().unwrap_or(0);
        if let Some(dst) = buf.get_mut(i.wrapping_sub(by)) {
            *dst = b;
        }
    }
}

/// The variable-length encoding of `n` (1 to 4 bytes) and its length.
pub fn remaining_length(n: usize) -> ([u8; 4], usize) {
    let mut out = [0u8; 4];
    let mut n = n.min(MAX_REMAINING);
    let mut len = 0;
    for slot in out.iter_mut() {
        let b = (n & 0x7F) as u8;
        n >>= 7;
        len += 1;
        if n == 0 {
            *slot = b;
            break;
        }
        *slot = b | 0x80;
    }
    (out, len)
}

/// Writes a packet of type byte `first` whose variable header and payload
/// `body` writes: the fixed header is put in front once the body's length
/// is known.
pub fn packet(w: &mut Writer<'_>, first: u8, body: impl FnOnce(&mut Writer<'_>)) {
    let start = w.len();
    w.put(&[first, 0, 0, 0, 0]);
    let body_at = w.len();
    body(w);
    let n = w.len().saturating_sub(body_at);
    if n > MAX_REMAINING {
        w.fail();
    }
    let (len, k) = remaining_length(n);
    w.patch(start + 1, len.get(..k).unwrap_or(&[]));
    w.close_gap(body_at, MAX_HEADER - 1 - k);
}

/// The Will of a CONNECT.
#[derive(Debug, Clone, Copy)]
pub struct Will<'a> {
    /// Its topic.
    pub topic: &'a [u8],
    /// Its message.
    pub payload: &'a [u8],
    /// Its QoS (Sparkplug: 1).
    pub qos: u8,
}

/// CONNECT, MQTT 3.1.1, clean session; the user name and password are
/// left out when empty.
pub fn connect(
    w: &mut Writer<'_>,
    client_id: &str,
    keep_alive_s: u16,
    will: Will<'_>,
    username: &str,
    password: &str,
) {
    packet(w, 0x10, |w| {
        w.field(b"MQTT");
        w.byte(4);
        let mut flags = 0b0000_0110 | (will.qos & 3) << 3;
        if !username.is_empty() {
            flags |= 0x80;
            if !password.is_empty() {
                flags |= 0x40;
            }
        }
        w.byte(flags);
        w.u16(keep_alive_s);
        w.field(client_id.as_bytes());
        w.field(will.topic);
        w.field(will.payload);
        if !username.is_empty() {
            w.field(username.as_bytes());
            if !password.is_empty() {
                w.field(password.as_bytes());
            }
        }
    });
}

/// PUBLISH to `topic` of the message that `payload` writes (not
/// retained).
pub fn publish(
    w: &mut Writer<'_>,
    topic: &[u8],
    qos: u8,
    id: u16,
    payload: impl FnOnce(&mut Writer<'_>),
) {
    packet(w, 0x30 | (qos & 3) << 1, |w| {
        w.field(topic);
        if qos > 0 {
            w.u16(id);
        }
        payload(w);
    });
}

/// SUBSCRIBE to `filters` (each with its QoS).
pub fn subscribe(w: &mut Writer<'_>, id: u16, filters: &[(&[u8], u8)]) {
    packet(w, 0x82, |w| {
        w.u16(id);
        for (filter, qos) in filters {
            w.field(filter);
            w.byte(*qos);
        }
    });
}

/// PUBACK.
pub fn puback(w: &mut Writer<'_>, id: u16) {
    w.put(&[0x40, 2]);
    w.u16(id);
}

/// PINGREQ.
pub fn pingreq(w: &mut Writer<'_>) {
    w.put(&[0xC0, 0]);
}

/// DISCONNECT.
pub fn disconnect(w: &mut Writer<'_>) {
    w.put(&[0xE0, 0]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn connect_with_will_and_credentials_as_the_standard_lays_it_out() {
        let mut buf = [0u8; 128];
        let mut w = Writer::new(&mut buf);
        let will = Will {
            topic: b"t/d",
            payload: b"\x01",
            qos: 1,
        };
        connect(&mut w, "gw", 30, will, "u", "p");
        assert!(!w.overflowed());
        assert_eq!(
            w.written(),
            [
                0x10,
                28,
                0,
                4,
                b'M',
                b'Q',
                b'T',
                b'T',
                4,
                0b1100_1110,
                0,
                30,
                0,
                2,
                b'g',
                b'w',
                0,
                3,
                b't',
                b'/',
                b'd',
                0,
                1,
                1,
                0,
                1,
                b'u',
                0,
                1,
                b'p'
            ]
        );
    }

    #[test]
    fn publish_and_its_reading_back_with_a_two_byte_length() {
        let mut buf = [0u8; 400];
        let mut w = Writer::new(&mut buf);
        let body = [7u8; 300];
        publish(&mut w, b"a/b", 1, 0x1234, |w| w.put(&body));
        let p = w.written();
        assert_eq!(p[..3], [0x32, 0xB3, 0x02]);
        assert_eq!(frame_len(p), Ok(Some(p.len())));
        assert_eq!(
            parse(p),
            Ok(Packet::Publish {
                topic: "a/b",
                qos: 1,
                id: Some(0x1234),
                payload: &body
            })
        );
    }

    #[test]
    fn a_packet_that_does_not_fit_is_marked() {
        let mut buf = [0u8; 8];
        let mut w = Writer::new(&mut buf);
        publish(&mut w, b"a/b", 0, 0, |w| w.put(&[1; 8]));
        assert!(w.overflowed());
    }

    #[test]
    fn broker_packets_and_broken_ones() {
        assert_eq!(parse(&[0x20, 2, 0, 0]), Ok(Packet::ConnAck { code: 0 }));
        assert_eq!(parse(&[0x20, 2, 0, 5]), Ok(Packet::ConnAck { code: 5 }));
        assert_eq!(
            parse(&[0x90, 4, 0, 1, 1, 0x80]),
            Ok(Packet::SubAck {
                id: 1,
                codes: &[1, 0x80]
            })
        );
        assert_eq!(parse(&[0xD0, 0]), Ok(Packet::PingResp));
        assert_eq!(parse(&[0x40, 2, 0, 9]), Ok(Packet::PubAck { id: 9 }));
        assert_eq!(frame_len(&[0x30]), Ok(None));
        assert_eq!(frame_len(&[0x30, 0x80, 0x80, 0x80, 0x80]), Err(Malformed));
        // A topic length past the end, QoS 3, a wrong length.
        assert_eq!(parse(&[0x30, 3, 0, 9, b'a']), Err(Malformed));
        assert_eq!(parse(&[0x36, 3, 0, 1, b'a']), Err(Malformed));
        assert_eq!(parse(&[0x20, 3, 0, 0]), Err(Malformed));
        assert_eq!(parse(&[0xF0, 0]), Err(Malformed));
    }
}
