//! The Sparkplug B payload (Eclipse Sparkplug 3.0, 6.4): a protobuf
//! (proto2) `Payload` of `Metric`s, as declared in `sparkplug_b.proto`
//! beside this file. Written straight into the MQTT packet being built
//! ([`super::mqtt::Writer`]), with no message structs in RAM; read field
//! by field from a received NCMD or DCMD ([`metrics`]), unknown fields
//! skipped by their wire type. Signed values travel as their two's
//! complement in the unsigned fields (Sparkplug 3.0, 6.4.16).

use super::mqtt::Writer;

/// Sparkplug data types (6.4.16) the node uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    /// Int32, in `int_value`.
    Int32 = 3,
    /// Int64, in `long_value`.
    Int64 = 4,
    /// UInt8, in `int_value`.
    UInt8 = 5,
    /// UInt16, in `int_value`.
    UInt16 = 6,
    /// UInt32, in `int_value`.
    UInt32 = 7,
    /// UInt64, in `long_value`.
    UInt64 = 8,
    /// Boolean, in `boolean_value`.
    Boolean = 11,
    /// String, in `string_value`.
    String = 12,
    /// Bytes, in `bytes_value`.
    Bytes = 17,
}

/// A metric's value as it is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Value<'a> {
    /// Int8..UInt32 (`int_value`, field 10).
    Int(u32),
    /// Int64, UInt64 (`long_value`, field 11).
    Long(u64),
    /// Boolean (field 14).
    Bool(bool),
    /// String (field 15).
    Str(&'a str),
    /// Bytes (field 16), here 16-bit words sent big-endian.
    Words(&'a [u16]),
}

/// Protobuf wire types.
const VARINT: u8 = 0;
const FIXED64: u8 = 1;
const LEN: u8 = 2;
const FIXED32: u8 = 5;

/// Payload fields (`Payload` in the .proto).
const PAYLOAD_TIMESTAMP: u8 = 1;
const PAYLOAD_METRICS: u8 = 2;
const PAYLOAD_SEQ: u8 = 3;
/// Metric fields (`Metric` in the .proto).
const METRIC_NAME: u8 = 1;
const METRIC_ALIAS: u8 = 2;
const METRIC_DATATYPE: u8 = 4;
const METRIC_IS_NULL: u8 = 7;
const METRIC_INT: u8 = 10;
const METRIC_LONG: u8 = 11;
const METRIC_FLOAT: u8 = 12;
const METRIC_DOUBLE: u8 = 13;
const METRIC_BOOL: u8 = 14;
const METRIC_STRING: u8 = 15;
const METRIC_BYTES: u8 = 16;

/// Writes a base-128 varint.
pub fn varint(w: &mut Writer<'_>, mut v: u64) {
    let mut buf = [0u8; 10];
    let mut n = 0;
    for slot in buf.iter_mut() {
        let b = (v & 0x7F) as u8;
        v >>= 7;
        n += 1;
        if v == 0 {
            *slot = b;
            break;
        }
        *slot = b | 0x80;
    }
    w.put(buf.get(..n).unwrap_or(&[]));
}

/// A field's key (a varint: fields from 16 on take two bytes).
fn key(w: &mut Writer<'_>, field: u8, wire: u8) {
    varint(w, u64::from(field) << 3 | u64::from(wire));
}

/// A length-delimited field whose bytes `body` writes (up to 16,383).
fn nested(w: &mut Writer<'_>, field: u8, body: impl FnOnce(&mut Writer<'_>)) {
    key(w, field, LEN);
    let at = w.len();
    w.put(&[0, 0]);
    body(w);
    let n = w.len().saturating_sub(at + 2);
    if n < 0x80 {
        w.patch(at, &[n as u8]);
        w.close_gap(at + 2, 1);
    } else if n < 0x4000 {
        w.patch(at, &[(n as u8) | 0x80, (n >> 7) as u8]);
    } else {
        // Too long for two length bytes: the packet is refused whole.
        w.fail();
    }
}

/// The payload's header: its timestamp (ms) and, but for NDEATH, `seq`.
pub fn header(w: &mut Writer<'_>, timestamp: u64, seq: Option<u8>) {
    key(w, PAYLOAD_TIMESTAMP, VARINT);
    varint(w, timestamp);
    if let Some(seq) = seq {
        key(w, PAYLOAD_SEQ, VARINT);
        varint(w, u64::from(seq));
    }
}

/// One metric: its name (BIRTH, with its data type) or only its alias
/// (DATA).
pub fn metric(
    w: &mut Writer<'_>,
    name: Option<&dyn Fn(&mut Writer<'_>)>,
    alias: Option<u16>,
    datatype: DataType,
    value: Value<'_>,
) {
    nested(w, PAYLOAD_METRICS, |w| {
        if let Some(name) = name {
            key(w, METRIC_NAME, LEN);
            let at = w.len();
            w.byte(0);
            name(w);
            let n = w.len().saturating_sub(at + 1);
            match u8::try_from(n) {
                Ok(n) if n < 0x80 => w.patch(at, &[n]),
                _ => w.fail(),
            }
        }
        if let Some(alias) = alias {
            key(w, METRIC_ALIAS, VARINT);
            varint(w, u64::from(alias));
        }
        if name.is_some() {
            key(w, METRIC_DATATYPE, VARINT);
            varint(w, datatype as u64);
        }
        match value {
            Value::Int(v) => {
                key(w, METRIC_INT, VARINT);
                varint(w, u64::from(v));
            }
            Value::Long(v) => {
                key(w, METRIC_LONG, VARINT);
                varint(w, v);
            }
            Value::Bool(v) => {
                key(w, METRIC_BOOL, VARINT);
                varint(w, u64::from(v));
            }
            Value::Str(s) => {
                key(w, METRIC_STRING, LEN);
                varint(w, s.len() as u64);
                w.put(s.as_bytes());
            }
            Value::Words(words) => {
                key(w, METRIC_BYTES, LEN);
                varint(w, 2 * words.len() as u64);
                for v in words {
                    w.u16(*v);
                }
            }
        }
    });
}

/// A received metric's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received<'a> {
    /// `int_value` or `long_value` (data type as the sender says).
    Int(u64),
    /// `boolean_value`.
    Bool(bool),
    /// `string_value`.
    Str(&'a str),
    /// `bytes_value`.
    Bytes(&'a [u8]),
    /// `float_value` or `double_value`, or `is_null`: no value the node
    /// takes.
    Other,
}

/// A metric of a received payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MetricIn<'a> {
    /// Its name, if sent.
    pub name: Option<&'a str>,
    /// Its alias, if sent.
    pub alias: Option<u64>,
    /// Its value.
    pub value: Received<'a>,
}

/// The payload is not a protobuf `Payload`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BadPayload;

/// Reads a varint at the head of `buf`: the value and the rest.
fn read_varint(buf: &[u8]) -> Result<(u64, &[u8]), BadPayload> {
    let mut v = 0u64;
    for (i, &b) in buf.iter().enumerate().take(10) {
        v |= u64::from(b & 0x7F) << (7 * i);
        if b & 0x80 == 0 {
            return Ok((v, buf.get(i + 1..).unwrap_or(&[])));
        }
    }
    Err(BadPayload)
}

/// A field: its number, wire type, its value (a varint as a number,
/// length-delimited as bytes; fixed numbers as neither) and what follows.
type Field<'a> = (u64, u8, u64, &'a [u8], &'a [u8]);

/// The field at the head of `buf`.
fn read_field(buf: &[u8]) -> Result<Field<'_>, BadPayload> {
    let (k, rest) = read_varint(buf)?;
    let (field, wire) = (k >> 3, (k & 7) as u8);
    match wire {
        VARINT => {
            let (v, rest) = read_varint(rest)?;
            Ok((field, wire, v, &[], rest))
        }
        FIXED64 | FIXED32 => {
            let n = if wire == FIXED64 { 8 } else { 4 };
            let rest = rest.get(n..).ok_or(BadPayload)?;
            Ok((field, wire, 0, &[], rest))
        }
        LEN => {
            let (n, rest) = read_varint(rest)?;
            let n = usize::try_from(n).map_err(|_| BadPayload)?;
            let bytes = rest.get(..n).ok_or(BadPayload)?;
            Ok((field, wire, 0, bytes, rest.get(n..).unwrap_or(&[])))
        }
        _ => Err(BadPayload),
    }
}

/// The metrics of a received payload, in order; the first malformed field
/// ends them with an error.
pub fn metrics(payload: &[u8]) -> impl Iterator<Item = Result<MetricIn<'_>, BadPayload>> {
    let mut rest = payload;
    core::iter::from_fn(move || loop {
        if rest.is_empty() {
            return None;
        }
        match read_field(rest) {
            Err(e) => {
                rest = &[];
                return Some(Err(e));
            }
            Ok((field, wire, _, bytes, next)) => {
                rest = next;
                if field == u64::from(PAYLOAD_METRICS) && wire == LEN {
                    let m = read_metric(bytes);
                    if m.is_err() {
                        rest = &[];
                    }
                    return Some(m);
                }
            }
        }
    })
}

fn read_metric(mut buf: &[u8]) -> Result<MetricIn<'_>, BadPayload> {
    let mut m = MetricIn {
        name: None,
        alias: None,
        value: Received::Other,
    };
    let mut null = false;
    while !buf.is_empty() {
        let (field, wire, v, bytes, rest) = read_field(buf)?;
        buf = rest;
        let Ok(field) = u8::try_from(field) else {
            continue;
        };
        match (field, wire) {
            (METRIC_NAME, LEN) => {
                m.name = Some(core::str::from_utf8(bytes).map_err(|_| BadPayload)?);
            }
            (METRIC_ALIAS, VARINT) => m.alias = Some(v),
            (METRIC_IS_NULL, VARINT) => null = v != 0,
            (METRIC_INT | METRIC_LONG, VARINT) => m.value = Received::Int(v),
            (METRIC_BOOL, VARINT) => m.value = Received::Bool(v != 0),
            (METRIC_STRING, LEN) => {
                m.value = Received::Str(core::str::from_utf8(bytes).map_err(|_| BadPayload)?);
            }
            (METRIC_BYTES, LEN) => m.value = Received::Bytes(bytes),
            (METRIC_FLOAT, FIXED32) | (METRIC_DOUBLE, FIXED64) => m.value = Received::Other,
            _ => {}
        }
    }
    if null {
        m.value = Received::Other;
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    #[test]
    fn a_metric_by_name_and_by_alias_as_protobuf_lays_it_out() {
        let mut buf = [0u8; 64];
        let mut w = Writer::new(&mut buf);
        header(&mut w, 1_000, Some(3));
        metric(
            &mut w,
            Some(&|w: &mut Writer<'_>| w.put(b"Axis 1/Position")),
            Some(100),
            DataType::Int32,
            Value::Int(-25_500i32 as u32),
        );
        let name_metric = [
            0x08, 0xE8, 0x07, // timestamp 1000
            0x18, 0x03, // seq 3
            0x12, 27, // metric, 27 bytes
            0x0A, 15, b'A', b'x', b'i', b's', b' ', b'1', b'/', b'P', b'o', b's', b'i', b't', b'i',
            b'o', b'n', 0x10, 100, // alias 100
            0x20, 3, // Int32
            0x50, 0xE4, 0xB8, 0xFE, 0xFF, 0x0F, // int_value 0xFFFF9C64
        ];
        assert_eq!(w.written(), name_metric);
        let got: Vec<_> = metrics(w.written()).collect();
        assert_eq!(
            got,
            [Ok(MetricIn {
                name: Some("Axis 1/Position"),
                alias: Some(100),
                value: Received::Int(0xFFFF_9C64)
            })]
        );
    }

    #[test]
    fn bytes_take_a_two_byte_key_and_a_two_byte_length() {
        let words = [0x1234u16; 70];
        let mut buf = [0u8; 200];
        let mut w = Writer::new(&mut buf);
        metric(
            &mut w,
            None,
            Some(175),
            DataType::Bytes,
            Value::Words(&words),
        );
        let out = w.written();
        // Metric (field 2), 147 bytes: alias 175, then field 16 (key
        // 0x82 0x01), 140 bytes.
        assert_eq!(out[..3], [0x12, 0x93, 0x01]);
        assert_eq!(out[3..6], [0x10, 0xAF, 0x01]);
        assert_eq!(out[6..9], [0x82, 0x01, 0x8C]);
        assert_eq!(out[9..11], [0x01, 0x12]);
        let m = metrics(out).next().unwrap().unwrap();
        assert_eq!(m.alias, Some(175));
        assert!(matches!(m.value, Received::Bytes(b) if b.len() == 140 && b[..2] == [0x12, 0x34]));
    }

    #[test]
    fn broken_payloads_end_with_an_error() {
        // A metric whose length runs past the end; a group wire type.
        assert_eq!(metrics(&[0x12, 9, 0x10]).next(), Some(Err(BadPayload)));
        assert_eq!(metrics(&[0x13]).next(), Some(Err(BadPayload)));
        // A float value is taken as no value; unknown fields are skipped.
        let m = [0x12, 7, 0x10, 5, 0x65, 0, 0, 0x80, 0x3F];
        assert_eq!(
            metrics(&m).next(),
            Some(Ok(MetricIn {
                name: None,
                alias: Some(5),
                value: Received::Other
            }))
        );
    }
}
