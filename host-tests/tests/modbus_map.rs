//! The README's register table is `iai modbus map`'s output, which is
//! generated from the firmware's one table (`modbus::map`): it cannot
//! drift from the source.

use std::process::Command;

use firmware_example::modbus::map::MAP;
use host_tests::qemu::{iai_binary, workspace_root};

#[test]
fn the_readme_table_is_the_map() {
    let readme = std::fs::read_to_string(workspace_root().join("README.md")).expect("README.md");
    let start = readme
        .find("<!-- register map -->")
        .expect("the register map's marker in README.md");
    let table: Vec<&str> = readme[start..]
        .lines()
        .skip(1)
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .collect();
    let iai = iai_binary().expect("the iai binary");
    let out = Command::new(iai)
        .args(["modbus", "map"])
        .output()
        .expect("run iai");
    assert!(out.status.success());
    let map = String::from_utf8(out.stdout).expect("UTF-8");
    let rows: Vec<&str> = map.lines().collect();
    if table != rows {
        println!("`iai modbus map` prints (paste it under the marker):\n{map}");
    }
    assert_eq!(table, rows);
    // One row per field of every entry, the header and its rule.
    let fields: usize = MAP.iter().map(|e| e.item.fields().list.len()).sum();
    assert_eq!(rows.len(), fields + 2);
}
