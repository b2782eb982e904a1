//! The declared layouts against `spec/messages.toml`.
//!
//! For every catalogue entry (complete or partial) and each direction, a
//! frame is generated from the catalogue's field table (widths, radix,
//! signedness, repeat rules), decoded with [`decode_any`], and what the Rust
//! type reports through its [`Fields`] visitor — names, widths, radix, sign,
//! values, group counts, count-field widths, maxima — must equal what the
//! catalogue says. The largest frame the reported layout allows must equal
//! the catalogue's frame maximum. Re-emitting must give the same bytes.
//!
//! Partial entries (290H, 291H, 2A3H) are checked against the catalogue's
//! chosen reading, including its **inferred** rows.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::*;
use iai_protocol_b::catalogue::{self, Generation, Status};
use iai_protocol_b::frame::Station;
use iai_protocol_b::message::{decode_any, AnyMessage, ErrorResponse, Fields};

fn decode_and_record(bytes: &[u8]) -> (Recorder, Vec<u8>) {
    let frame = check(bytes);
    let decoded = decode_any(&frame)
        .unwrap_or_else(|e| panic!("{} does not decode: {e}", String::from_utf8_lossy(bytes)));
    let mut rec = Recorder::default();
    decoded.message.fields(&mut rec);
    let mut out = vec![0u8; bytes.len() + 64];
    let n = match &decoded.message {
        AnyMessage::Command(c) => c.emit(Station(0x99), &mut out),
        AnyMessage::Response(r) => r.emit(Station(0x99), &mut out),
        AnyMessage::Error(e) => e.emit(Station(0x99), &mut out),
    }
    .unwrap();
    out.truncate(n);
    (rec, out)
}

fn check_part(m: &Msg, part: Part, mode: Mode) -> Vec<Ev> {
    let groups = m.groups(part);
    let nodes = tree(m.fields(part), &groups);
    let mut gen = Gen::new(mode);
    let (mut body, mut expected) = (String::new(), Vec::new());
    generate(&nodes, &mut gen, &mut body, &mut expected);
    let bytes = frame_text(part.header(), &m.id, &body);
    let (rec, again) = decode_and_record(&bytes);
    assert_eq!(
        rec.events,
        expected,
        "{} {}: layout differs for {}",
        m.id,
        part.name(),
        String::from_utf8_lossy(&bytes)
    );
    assert_eq!(
        again,
        bytes,
        "{} {}: re-emitted frame differs",
        m.id,
        part.name()
    );
    // Units: the Rust unit must be the catalogue's (or its first alternative).
    for (name, unit) in &rec.units {
        let toml = m.fields(part).iter().find(|f| &f.name == name).unwrap();
        assert!(
            toml.unit == *unit || (!unit.is_empty() && toml.unit.starts_with(unit.as_str())),
            "{} {} {name}: unit {unit:?} vs catalogue {:?}",
            m.id,
            part.name(),
            toml.unit
        );
    }
    rec.events
}

#[test]
fn every_layout_matches_the_catalogue() {
    let cat = catalogue();
    let mut checked = 0;
    for m in cat.message.iter().filter(|m| m.id != "ERR") {
        assert!(m.status == "complete" || m.status == "partial");
        for part in [Part::Command, Part::Response] {
            if part == Part::Response && m.has_normal_response == Some(false) {
                continue;
            }
            for seed in 0..40 {
                check_part(m, part, Mode::Random(seed));
            }
            check_part(m, part, Mode::Min);
            let events = check_part(m, part, Mode::Max);
            if let Some(max) = m.frame_max(part) {
                assert_eq!(
                    max_len(&events),
                    max,
                    "{} {} frame maximum",
                    m.id,
                    part.name()
                );
            }
            checked += 1;
        }
    }
    assert_eq!(checked, 54 * 2 - 1);
}

#[test]
fn catalogue_ids_names_status_generation_and_replies() {
    let cat = catalogue();
    let ids: Vec<u16> = cat
        .message
        .iter()
        .filter(|m| m.id != "ERR")
        .map(Msg::code)
        .collect();
    let core_ids: Vec<u16> = catalogue::ALL.iter().map(|m| m.id).collect();
    assert_eq!(ids, core_ids);
    for m in cat.message.iter().filter(|m| m.id != "ERR") {
        let info = catalogue::lookup(m.code()).unwrap();
        assert!(
            m.name.starts_with(info.name),
            "{}: {:?} vs {:?}",
            m.id,
            info.name,
            m.name
        );
        let status = if m.status == "partial" {
            Status::Partial
        } else {
            Status::Complete
        };
        assert_eq!(info.status, status, "{}", m.id);
        assert_eq!(
            info.has_normal_response(),
            m.has_normal_response.unwrap_or(true),
            "{}",
            m.id
        );
        // Messages laid out from TTA pages only are the TTA generation's.
        let generation = if m.layout_source == "tta" {
            Generation::Tta
        } else {
            Generation::Xsel2003
        };
        assert_eq!(info.since, generation, "{}", m.id);
    }
    assert_eq!(catalogue::lookup(0x217), None);
}

#[test]
fn error_response_matches_the_catalogue() {
    let cat = catalogue();
    let err = cat.message.iter().find(|m| m.id == "ERR").unwrap();
    assert_eq!(err.response.len(), 1);
    assert_eq!(err.response[0].width, 3);
    assert_eq!(err.response_frame_max, Some(10));
    let bytes = frame_text('&', "ABC", "");
    let frame = check(&bytes);
    assert_eq!(
        ErrorResponse::parse(&frame).unwrap(),
        ErrorResponse { code: 0xABC }
    );
    let mut out = [0u8; 10];
    assert_eq!(
        ErrorResponse { code: 0xABC }
            .emit(Station(0x99), &mut out)
            .unwrap(),
        10
    );
    assert_eq!(&out[..], &bytes[..]);
}

#[test]
fn no_response_type_for_software_reset() {
    let bytes = frame_text('#', "25B", "");
    let frame = check(&bytes);
    assert_eq!(
        decode_any(&frame).unwrap_err(),
        iai_protocol_b::error::Error::UnknownMessageId { id: 0x25B }
    );
}
