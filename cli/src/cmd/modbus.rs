//! `iai modbus map`: the gateway's register map, from its one table
//! (`firmware_example::modbus::map`: the entries and their fields), as a
//! Markdown table (the README's, field by field), or every address of
//! every axis and repetition as CSV, JSON lines or a KEPServerEX tag
//! import (its CSV tag columns; Modbus addresses in its 6-digit form).

use std::io::{self, Write};
use std::process::ExitCode;

use firmware_example::modbus::map::{self, Access, Entry, Field, Space, Type, MAP};
use serde::Serialize;

use super::{out_err, Run};

/// Examples for `iai modbus map --help`.
pub(crate) const MAP_HELP: &str = "\
Examples:
  iai modbus map                      the map as a Markdown table, field by field (the README's)
  iai modbus map --csv > map.csv      every register and bit of every axis: address, functions, name, type, unit, access, meaning
  iai modbus map --json | jq .name    the same, one JSON object per line
  iai modbus map --kepware > tags.csv a KEPServerEX tag import (Device > Import CSV); set the device's
                                      \"First word low\" off: 32-bit values are high word first

Addresses are PDU addresses (from 0, as mbpoll -0 and pymodbus take them);
bits of a register are ADDRESS.BIT. The KEPServerEX form counts from 1
(400001 is holding register 0).";

/// The output form.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Form {
    Markdown,
    Csv,
    Json,
    Kepware,
}

/// One register, register pair, bit or byte of one axis or repetition.
#[derive(Serialize)]
pub(crate) struct Tag {
    /// Its data space.
    #[serde(skip)]
    space: Space,
    /// PDU address of its (first) register, coil or input.
    address: u16,
    /// The bit of the register, for a bit.
    bit: Option<u8>,
    /// The function codes that reach it.
    functions: Vec<&'static str>,
    /// Tag name: axis, entry, repetition, field.
    name: String,
    #[serde(rename = "type")]
    ty: &'static str,
    unit: &'static str,
    /// R (read only) or RW.
    access: &'static str,
    meaning: &'static str,
    /// The map entry and field it belongs to.
    entry: &'static str,
    field: &'static str,
    /// Axis 1..=8 of a per-axis entry.
    axis: Option<u8>,
    /// Number of the repetition (record, variable, port).
    index: Option<u16>,
    /// The protocol-B message it is read from or written with.
    protocol_b: Option<String>,
    /// What completes a write (command entries).
    done: Option<&'static str>,
}

fn type_name(ty: Type) -> &'static str {
    match ty {
        Type::U16 => "uint16",
        Type::I32 => "int32",
        Type::U32 => "uint32",
        Type::Bits => "bits16",
        Type::Bit(_) => "bit",
        Type::Low8 => "uint8 (low byte)",
        Type::Bool => "bool",
    }
}

/// The function codes that reach an entry.
fn functions(e: &Entry) -> Vec<&'static str> {
    match (e.space, e.access) {
        (Space::Registers, Access::Read) => vec!["03", "04"],
        (Space::Registers, _) => vec!["03", "06", "16"],
        (Space::Coils, _) => vec!["01", "05", "15"],
        (Space::Discretes, _) => vec!["02"],
    }
}

fn access(e: &Entry) -> &'static str {
    match e.access {
        Access::Read => "R",
        Access::Setting | Access::Command => "RW",
    }
}

/// Every tag of the map, in the table's order: each axis of a per-axis
/// entry, each repetition, each field.
pub(crate) fn tags() -> Vec<Tag> {
    let mut out = Vec::new();
    for e in MAP {
        let fs = e.item.fields();
        for block in 0..e.blocks {
            let axis = (e.blocks > 1).then_some(block + 1);
            let base = e.start + u16::from(block) * map::AXIS_STRIDE;
            for k in 0..fs.repeat {
                let index = (fs.repeat > 1).then_some(fs.first + k);
                for f in fs.list {
                    out.push(tag(e, f, base + k * fs.stride + f.offset, axis, index));
                }
            }
        }
    }
    out
}

fn tag(
    e: &'static Entry,
    f: &'static Field,
    address: u16,
    axis: Option<u8>,
    index: Option<u16>,
) -> Tag {
    let mut name = String::new();
    if let Some(a) = axis {
        name.push_str(&format!("AX{a}_"));
    }
    name.push_str(e.name);
    if let Some(i) = index {
        name.push_str(&i.to_string());
    }
    if f.name != e.name {
        name.push('_');
        name.push_str(f.name);
    }
    Tag {
        space: e.space,
        address,
        bit: match f.ty {
            Type::Bit(b) => Some(b),
            _ => None,
        },
        functions: functions(e),
        name,
        ty: type_name(f.ty),
        unit: f.unit,
        access: access(e),
        meaning: f.meaning,
        entry: e.name,
        field: f.name,
        axis,
        index,
        protocol_b: e.message.map(|m| format!("{:03X}H", m.id)),
        done: (e.access == Access::Command).then_some(map::DONE),
    }
}

/// An address as the README and the CSV write it.
fn address_text(space: Space, address: u16, bit: Option<u8>) -> String {
    let a = match space {
        Space::Registers => format!("{address:04X}H"),
        _ => address.to_string(),
    };
    match bit {
        Some(b) => format!("{a} bit {b}"),
        None => a,
    }
}

/// The Markdown table: one row per field, per-axis entries and
/// repetitions written once with their step.
pub(crate) fn markdown() -> String {
    let mut s = String::from(
        "| address | name | type | unit | functions | repeats | meaning |\n|---|---|---|---|---|---|---|\n",
    );
    for e in MAP {
        let fs = e.item.fields();
        let mut repeats = Vec::new();
        if e.blocks > 1 {
            repeats.push(format!("axes 1-{}, +{:X}H", e.blocks, map::AXIS_STRIDE));
        }
        if fs.repeat > 1 {
            let step = match e.space {
                Space::Registers => format!("{:X}H", fs.stride),
                _ => fs.stride.to_string(),
            };
            let last = fs.first + fs.repeat - 1;
            repeats.push(format!("{} {}-{last}, +{step}", fs.counts, fs.first));
        }
        for f in fs.list {
            let bit = match f.ty {
                Type::Bit(b) => Some(b),
                _ => None,
            };
            let name = if f.name == e.name {
                e.name.to_owned()
            } else {
                format!("{}.{}", e.name, f.name)
            };
            s.push_str(&format!(
                "| {} | {name} | {} | {} | {} | {} | {} |\n",
                address_text(e.space, e.start + f.offset, bit),
                type_name(f.ty),
                f.unit,
                functions(e).join(" "),
                repeats.join("; "),
                f.meaning
            ));
        }
    }
    s
}

/// The KEPServerEX address of a tag: 6-digit Modbus numbering from 1
/// (0xxxxx coils, 1xxxxx discrete inputs, 4xxxxx holding registers; the
/// read-only registers are read as holding registers too), `.bb` for a
/// bit of a register.
fn kepware_address(t: &Tag) -> String {
    let n = u32::from(t.address) + 1;
    let a = match t.space {
        Space::Coils => format!("0{n:05}"),
        Space::Discretes => format!("1{n:05}"),
        Space::Registers => format!("4{n:05}"),
    };
    match t.bit {
        Some(b) => format!("{a}.{b:02}"),
        None => a,
    }
}

fn kepware_type(ty: &str) -> &'static str {
    match ty {
        "int32" => "Long",
        "uint32" => "DWord",
        "bit" | "bool" => "Boolean",
        _ => "Word",
    }
}

/// The KEPServerEX tag CSV columns.
const KEPWARE_HEADER: [&str; 16] = [
    "Tag Name",
    "Address",
    "Data Type",
    "Respect Data Type",
    "Client Access",
    "Scan Rate",
    "Scaling",
    "Raw Low",
    "Raw High",
    "Scaled Low",
    "Scaled High",
    "Scaled Data Type",
    "Clamp Low",
    "Clamp High",
    "Eng Units",
    "Description",
];

/// Prints the map in `form`.
pub(crate) fn map_cmd(form: Form) -> Run {
    let stdout = io::stdout();
    let mut out = stdout.lock();
    write_map(&mut out, form).map_err(out_err)?;
    out.flush().map_err(out_err)?;
    Ok(ExitCode::SUCCESS)
}

fn csv_err(e: csv::Error) -> io::Error {
    match e.into_kind() {
        csv::ErrorKind::Io(e) => e,
        other => io::Error::other(format!("{other:?}")),
    }
}

/// Writes the map in `form` to `out`.
pub(crate) fn write_map(out: &mut dyn Write, form: Form) -> io::Result<()> {
    match form {
        Form::Markdown => out.write_all(markdown().as_bytes()),
        Form::Json => {
            for t in tags() {
                serde_json::to_writer(&mut *out, &t)?;
                out.write_all(b"\n")?;
            }
            Ok(())
        }
        Form::Csv => {
            let mut w = csv::Writer::from_writer(out);
            let head = [
                "address",
                "functions",
                "name",
                "type",
                "unit",
                "access",
                "meaning",
            ];
            w.write_record(head).map_err(csv_err)?;
            for t in tags() {
                let address = match t.bit {
                    Some(b) => format!("{}.{b}", t.address),
                    None => t.address.to_string(),
                };
                let functions = t.functions.join(" ");
                let row = [
                    &address, &functions, &t.name, t.ty, t.unit, t.access, t.meaning,
                ];
                w.write_record(row).map_err(csv_err)?;
            }
            w.flush()
        }
        Form::Kepware => {
            let mut w = csv::Writer::from_writer(out);
            w.write_record(KEPWARE_HEADER).map_err(csv_err)?;
            for t in tags() {
                let access = if t.access == "R" { "RO" } else { "R/W" };
                let ty = kepware_type(t.ty);
                let address = kepware_address(&t);
                let row = [
                    t.name.as_str(),
                    &address,
                    ty,
                    "1",
                    access,
                    "100",
                    "",
                    "",
                    "",
                    "",
                    "",
                    "",
                    "",
                    "",
                    t.unit,
                    t.meaning,
                ];
                w.write_record(row).map_err(csv_err)?;
            }
            w.flush()
        }
    }
}
