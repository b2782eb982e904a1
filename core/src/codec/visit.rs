//! Showing decoded values: the [`Visitor`] that receives the fields of a
//! message in wire order, with their names, units and wire formats, and
//! the [`Inspect`] trait every codec implements to feed it. Loggers,
//! inspectors and the catalogue checks walk messages through [`Fields`].

use crate::field::FieldSpec;

/// A decoded value as shown to a [`Visitor`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Value<'v> {
    /// An unsigned numeric field (bit patterns, counts, numbers).
    Unsigned(u64),
    /// A signed (two's complement) numeric field.
    Signed(i64),
    /// Raw characters: a text field or the literal of a reserved field.
    Text(&'v [u8]),
}

/// How one repeat group looks on the wire, for a [`Visitor`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GroupInfo {
    /// Items in this instance of the group.
    pub count: usize,
    /// Format of the count field that precedes the group, if it has one
    /// (axis-pattern and fixed-size groups have none).
    pub count_field: Option<FieldSpec>,
    /// Units the count field counts per item (8 for port and flag bytes,
    /// 1 elsewhere).
    pub per_item: usize,
    /// The value the count field holds: `count`, or for port and flag
    /// groups the number of ports or flags (`count` is that divided by 8,
    /// rounded up).
    pub units: usize,
    /// Largest item count the declaration accepts.
    pub max: usize,
}

/// Receives the fields of a message in wire order (see [`Fields`]).
pub trait Visitor {
    /// One leaf field: its name, unit (`""` if none), wire format and value.
    fn field(&mut self, name: &'static str, unit: &'static str, spec: FieldSpec, value: Value<'_>);
    /// A repeat group starts; its items follow, then [`Visitor::leave_group`].
    fn enter_group(&mut self, name: &'static str, group: GroupInfo) {
        let _ = (name, group);
    }
    /// The repeat group opened last ends.
    fn leave_group(&mut self) {}
}

/// Walks the fields of a value in wire order. Derived by `wire!`.
pub trait Fields {
    /// Calls `v` once per leaf field and around every repeat group.
    fn fields(&self, v: &mut dyn Visitor);
}

/// A codec that can show values of type `T` to a [`Visitor`].
pub trait Inspect<T: ?Sized> {
    /// Reports `value` as field `name` with `unit`.
    fn inspect(&self, value: &T, name: &'static str, unit: &'static str, v: &mut dyn Visitor);
}

pub(crate) fn inspect_items<'i, T: 'i, C: Inspect<T>>(
    codec: &C,
    items: impl Iterator<Item = &'i T>,
    name: &'static str,
    unit: &'static str,
    group: GroupInfo,
    v: &mut dyn Visitor,
) {
    v.enter_group(name, group);
    items.for_each(|item| codec.inspect(item, name, unit, v));
    v.leave_group();
}

/// `stringify!` of a raw identifier keeps its `r#`; field names shown to a
/// [`Visitor`] drop it (`r#type` → `type`).
#[doc(hidden)]
pub const fn strip_raw(name: &'static str) -> &'static str {
    match name.as_bytes() {
        [b'r', b'#', rest @ ..] => match core::str::from_utf8(rest) {
            Ok(s) => s,
            Err(_) => name,
        },
        _ => name,
    }
}
