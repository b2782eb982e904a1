//! The README's register table is the source table, row for row.

use firmware_example::modbus::map::{Access, Space, MAP};

/// The README row of each entry of the map.
fn rows() -> Vec<String> {
    MAP.iter()
        .map(|e| {
            let space = match e.space {
                Space::Coils => "coils",
                Space::Discretes => "discrete inputs",
                Space::Registers => "registers",
            };
            let address = match e.space {
                Space::Registers => format!("{:04X}H", e.start),
                _ => format!("{}", e.start),
            };
            let access = match e.access {
                Access::Read => "read (03, 04)",
                Access::Setting => "read 03, write 06/16 (kept in the gateway)",
                Access::Command => match e.space {
                    Space::Registers => "read 03, write 06/16 (a command)",
                    _ => "read 01, write 05 (a command)",
                },
            };
            let access = if e.space == Space::Discretes {
                "read (02)"
            } else {
                access
            };
            let message = e
                .message
                .map_or(String::new(), |m| format!("{:03X}H", m.id));
            let blocks = if e.blocks > 1 {
                format!("{} per axis, axes 1-{}", e.size, e.blocks)
            } else {
                e.size.to_string()
            };
            format!(
                "| {} | {space} | {address} | {blocks} | {access} | {message} | {} |",
                e.name, e.meaning
            )
        })
        .collect()
}

#[test]
fn the_readme_table_is_the_map() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md"))
        .expect("README.md");
    let start = readme
        .find("<!-- register map -->")
        .expect("the register map's marker in README.md");
    let table: Vec<&str> = readme[start..]
        .lines()
        .skip(1)
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .skip(2)
        .collect();
    let rows = rows();
    if table != rows {
        println!("The table the map gives:\n{}", rows.join("\n"));
    }
    assert_eq!(table, rows);
}
