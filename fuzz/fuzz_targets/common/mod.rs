//! Shared by the `decoder` and `frame_parse` targets: typed decoding of any
//! frame through `decode_any`, with a field visitor that checks what it is
//! shown.
#![allow(dead_code)]

use iai_protocol_b::field::{FieldSpec, Radix};
use iai_protocol_b::frame::Frame;
use iai_protocol_b::message::{decode_any, AnyMessage, Decoded, Fields, GroupInfo, Value, Visitor};

/// Checks every field the visitor is shown and adds up the wire widths.
#[derive(Default)]
pub struct CheckVisitor {
    /// Body bytes accounted for: leaf field widths plus count fields.
    pub wire_len: usize,
    /// Open groups.
    depth: usize,
    pub leaves: usize,
}

impl Visitor for CheckVisitor {
    fn field(
        &mut self,
        name: &'static str,
        _unit: &'static str,
        spec: FieldSpec,
        value: Value<'_>,
    ) {
        assert!(!name.is_empty());
        assert!(spec.is_valid(), "{name}: invalid spec {spec:?}");
        match value {
            Value::Unsigned(v) => {
                assert!(
                    !spec.signed && spec.radix != Radix::Text,
                    "{name}: {spec:?}"
                );
                assert!(
                    v <= spec.max_unsigned(),
                    "{name}: {v} does not fit {spec:?}"
                );
            }
            Value::Signed(v) => {
                assert!(spec.signed && spec.radix != Radix::Text, "{name}: {spec:?}");
                let (lo, hi) = spec.signed_range();
                assert!(lo <= v && v <= hi, "{name}: {v} does not fit {spec:?}");
            }
            Value::Text(t) => assert_eq!(t.len(), spec.len(), "{name}: {spec:?}"),
        }
        self.wire_len += spec.len();
        self.leaves += 1;
    }
    fn enter_group(&mut self, name: &'static str, group: GroupInfo) {
        assert!(!name.is_empty());
        assert!(group.count <= group.max, "{name}: {group:?}");
        if let Some(c) = group.count_field {
            assert!(c.is_valid());
            self.wire_len += c.len();
        }
        self.depth += 1;
    }
    fn leave_group(&mut self) {
        assert!(self.depth > 0, "leave_group without enter_group");
        self.depth -= 1;
    }
}

/// `decode_any` on a checked frame; if it decodes, walks the fields and
/// checks that they account for every body byte.
pub fn decode_and_visit<'a>(f: &Frame<'a>) -> Option<AnyMessage<'a>> {
    let Decoded { frame, message } = decode_any(f).ok()?;
    assert_eq!(frame, *f);
    let mut v = CheckVisitor::default();
    message.fields(&mut v);
    assert_eq!(v.depth, 0, "unbalanced groups");
    let body = match message {
        // The error code is shown as a field; it is not in the body.
        AnyMessage::Error(_) => 3,
        _ => f.body().len(),
    };
    assert_eq!(
        v.wire_len, body,
        "the fields do not cover the body: {message:?}"
    );
    Some(message)
}
