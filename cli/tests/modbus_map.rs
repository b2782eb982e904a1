//! `iai modbus map` against the firmware's own table: every register and
//! bit the gateway serves (`map::find` over the whole address space, all
//! eight axes) is in the CSV exactly once, with the type, unit and access
//! of its field; the JSON lines and the KEPServerEX import carry the same
//! tags.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::collections::BTreeMap;

use common::{iai, stdout};
use firmware_example::modbus::map::{self, Access, Space, MAP};

/// `iai modbus map ARGS`, which must succeed.
fn map_out(args: &[&str]) -> String {
    let mut all = vec!["modbus", "map"];
    all.extend_from_slice(args);
    let out = iai(&all);
    assert!(out.status.success(), "{all:?}");
    stdout(&out)
}

fn space_of(functions: &str) -> Space {
    match functions {
        "01 05 15" => Space::Coils,
        "02" => Space::Discretes,
        _ => Space::Registers,
    }
}

#[test]
fn the_csv_holds_every_address_the_gateway_serves_once() {
    let text = map_out(&["--csv"]);
    let mut rows = csv::Reader::from_reader(text.as_bytes());
    let head = rows.headers().unwrap().clone();
    assert_eq!(
        head.iter().collect::<Vec<_>>(),
        [
            "address",
            "functions",
            "name",
            "type",
            "unit",
            "access",
            "meaning"
        ]
    );
    // (space, address) -> the width-carrying rows' names; bits apart.
    let mut words: BTreeMap<(u8, u16), Vec<String>> = BTreeMap::new();
    let mut bits = 0;
    let mut names = std::collections::BTreeSet::new();
    for r in rows.records() {
        let r = r.unwrap();
        let (addr, ty) = (&r[0], &r[3]);
        let space = space_of(&r[1]);
        assert!(names.insert(r[2].to_owned()), "tag name twice: {}", &r[2]);
        // The entry the source table puts at the address: its access.
        let base: u16 = addr.split('.').next().unwrap().parse().unwrap();
        let at = map::find(space, base, 8).unwrap_or_else(|| panic!("{addr} not in the map"));
        let want = if at.entry.access == Access::Read {
            "R"
        } else {
            "RW"
        };
        assert_eq!(&r[5], want, "{}", &r[2]);
        let width = match ty {
            "int32" | "uint32" => 2,
            "bit" | "uint8 (low byte)" => {
                bits += 1;
                assert!(ty != "bit" || addr.contains('.'), "{addr}");
                0
            }
            _ => 1,
        };
        for i in 0..width {
            let key = (space as u8, base + i);
            words.entry(key).or_default().push(r[2].to_owned());
        }
        // The unit of a position is the SEL's.
        if r[2].ends_with("_PNOW") || r[2].contains("_POS") && !r[2].ends_with("_POSR") {
            assert_eq!((&r[3], &r[4]), ("int32", "0.001 mm"), "{}", &r[2]);
        }
    }
    // Every mapped address of each space, and nothing else, exactly once.
    for space in [Space::Coils, Space::Discretes, Space::Registers] {
        for addr in 0..=u16::MAX {
            let mapped = map::find(space, addr, 8).is_some();
            let got = words.get(&(space as u8, addr)).map_or(0, Vec::len);
            assert_eq!(
                got,
                usize::from(mapped),
                "{space:?} {addr}: {:?}",
                words.get(&(space as u8, addr))
            );
        }
    }
    assert_eq!(words.len() as u32, map::size().0 + map::size().1);
    // The bits of DRG1, DSS1 (8 axes each) and CMDST.
    assert_eq!(bits, 8 * 5 + 8 * 6 + 4);
    // Spot checks: DSS1 of axis 2, MOVE; PNOW of axis 8.
    assert!(
        text.contains("\n36885.5,03 04,AX2_DSS1_MOVE,bit,,R,"),
        "{text}"
    );
    assert!(text.contains("\n36976,03 04,AX8_PNOW,int32,0.001 mm,R,"));
}

#[test]
fn json_and_kepware_carry_the_same_tags() {
    let csv_text = map_out(&["--csv"]);
    let names: Vec<String> = csv::Reader::from_reader(csv_text.as_bytes())
        .records()
        .map(|r| r.unwrap()[2].to_owned())
        .collect();
    let json = map_out(&["--json"]);
    let objects: Vec<serde_json::Value> = json
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let json_names: Vec<&str> = objects
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    assert_eq!(json_names, names);
    let pnow = objects.iter().find(|o| o["name"] == "AX1_PNOW").unwrap();
    assert_eq!(pnow["address"], 0x9000);
    assert_eq!(pnow["protocol_b"], "212H");
    assert_eq!(pnow["axis"], 1);
    let servo = objects
        .iter()
        .find(|o| o["name"] == "AX3_DRG1_SON")
        .unwrap();
    assert_eq!(
        (servo["address"].as_u64(), servo["bit"].as_u64()),
        (Some(0x0D20), Some(12))
    );
    assert_eq!(servo["done"], map::DONE);
    // KEPServerEX: its columns, 6-digit addresses from 1.
    let kep = map_out(&["--kepware"]);
    let mut rows = csv::Reader::from_reader(kep.as_bytes());
    assert_eq!(
        &rows.headers().unwrap().iter().take(5).collect::<Vec<_>>(),
        &[
            "Tag Name",
            "Address",
            "Data Type",
            "Respect Data Type",
            "Client Access"
        ]
    );
    let kep: Vec<csv::StringRecord> = rows.records().map(Result::unwrap).collect();
    assert_eq!(
        kep.iter().map(|r| r[0].to_owned()).collect::<Vec<_>>(),
        names
    );
    let row = |name: &str| -> Vec<String> {
        let r = kep.iter().find(|r| &r[0] == name).unwrap();
        r.iter().map(str::to_owned).collect()
    };
    assert_eq!(&row("AX1_PNOW")[1..5], ["436865", "Long", "1", "RO"]);
    assert_eq!(
        &row("AX1_DRG1_SON")[1..5],
        ["403329.12", "Boolean", "1", "R/W"]
    );
    assert_eq!(&row("OUT300")[1..3], ["000301", "Boolean"]);
    assert_eq!(&row("IN0")[1..3], ["100001", "Boolean"]);
    assert_eq!(&row("INTV200")[1..3], ["408417", "Long"]);
    assert_eq!(&row("PWREC5_POS8")[1..3], ["408808", "Long"]);
    // One tag per entry and field of the table, times axes and repeats.
    let want: usize = MAP
        .iter()
        .map(|e| {
            let fs = e.item.fields();
            usize::from(e.blocks) * usize::from(fs.repeat) * fs.list.len()
        })
        .sum();
    assert_eq!(kep.len(), want);
}
