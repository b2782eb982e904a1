//! Position tables as CSV, the form people keep them in spreadsheets.
//!
//! ```text
//! number,acceleration,deceleration,speed,axis1,axis2,axis3
//! 1,0.30,0.30,100,100.000,-25.500,
//! 2,0.00,0.00,0,12.345,,7.000
//! ```
//!
//! - `number`: the position number (the write message's number field).
//! - `acceleration`, `deceleration`: G, at most 2 decimals (0.01 G on the
//!   wire; 0 = the controller's parameter).
//! - `speed`: mm/s, an integer (0 = the controller's parameter).
//! - `axis1` … `axis8` (fewer columns allowed, in order): mm with at most 3
//!   decimals (0.001 mm on the wire); on a rotary axis the same column is
//!   degrees (0.001°). An empty cell means the axis is not in the record.
//!
//! Every range is the wire field's, taken from the core's field specs.
//! Writing: every cell of every row is checked before anything is sent;
//! errors name the line, the column and the allowed range.

use std::collections::BTreeMap;
use std::io::{Read, Write};

use iai_protocol_b::axis::{AxisPattern, PerAxis, MAX_AXES};
use iai_protocol_b::field::FieldSpec;
use iai_protocol_b::position::{PositionRecord, RecordLayout};

/// Fixed columns before the axes.
pub const FIXED: [&str; 4] = ["number", "acceleration", "deceleration", "speed"];

/// Wire formats of the record fields (the core's layout: 4-digit hex
/// acceleration, deceleration and speed, signed 8-digit coordinates).
const ACC: FieldSpec = FieldSpec::hex(4);
const COORD: FieldSpec = FieldSpec::signed_hex(8);

/// One bad cell (or header).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CellError {
    /// 1-based line of the file.
    pub line: u64,
    /// Column name (or `header`).
    pub column: String,
    /// What is wrong, with the allowed range.
    pub message: String,
}

impl std::fmt::Display for CellError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "line {}, column {}: {}",
            self.line, self.column, self.message
        )
    }
}

/// A decimal with at most `decimals` digits after the point, scaled to an
/// integer: `"-12.3"` with 3 decimals is `-12300`. Strict: one optional
/// leading `-`, digits, an optional point with digits after it.
pub fn parse_scaled(s: &str, decimals: u32) -> Result<i64, String> {
    let (neg, body) = match s.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, s),
    };
    let (int, frac) = match body.split_once('.') {
        Some((i, f)) => (i, f),
        None => (body, ""),
    };
    let digits = |t: &str| t.bytes().all(|b| b.is_ascii_digit());
    if int.is_empty() || !digits(int) || !digits(frac) || (body.contains('.') && frac.is_empty()) {
        return Err(format!("{s:?} is not a number"));
    }
    if frac.len() > decimals as usize {
        return Err(format!("{s:?} has more than {decimals} decimal(s)"));
    }
    let scale = 10i64.pow(decimals);
    let mut f: i64 = if frac.is_empty() {
        0
    } else {
        frac.parse().map_err(|_| format!("{s:?} is not a number"))?
    };
    f *= 10i64.pow(decimals - frac.len() as u32);
    let i: i64 = int.parse().map_err(|_| format!("{s:?} is out of range"))?;
    let v = i
        .checked_mul(scale)
        .and_then(|v| v.checked_add(f))
        .ok_or_else(|| format!("{s:?} is out of range"))?;
    Ok(if neg { -v } else { v })
}

/// `v` / 10^decimals with exactly `decimals` decimals.
pub fn format_scaled(v: i64, decimals: u32) -> String {
    let scale = 10i64.pow(decimals);
    let sign = if v < 0 { "-" } else { "" };
    let a = v.unsigned_abs();
    let s = scale as u64;
    if decimals == 0 {
        return format!("{sign}{a}");
    }
    format!("{sign}{}.{:0w$}", a / s, a % s, w = decimals as usize)
}

fn range_text(lo: i64, hi: i64, decimals: u32, unit: &str) -> String {
    let r = format!(
        "{}..={}",
        format_scaled(lo, decimals),
        format_scaled(hi, decimals)
    );
    if unit.is_empty() {
        r
    } else {
        format!("{r} {unit}")
    }
}

fn field_range(spec: FieldSpec) -> (i64, i64) {
    if spec.signed {
        spec.signed_range()
    } else {
        (0, i64::try_from(spec.max_unsigned()).unwrap_or(i64::MAX))
    }
}

fn cell(raw: &str, spec: FieldSpec, decimals: u32, unit: &str) -> Result<i64, String> {
    let (lo, hi) = field_range(spec);
    let range = range_text(lo, hi, decimals, unit);
    let v = parse_scaled(raw, decimals).map_err(|e| format!("{e}; allowed {range}"))?;
    if v < lo || v > hi {
        return Err(format!("{raw:?} is outside {range}"));
    }
    Ok(v)
}

/// Errors shown at most; the check goes on counting after them.
pub const SHOWN_ERRORS: usize = 50;

/// What is wrong with a CSV table: the first [`SHOWN_ERRORS`] errors, how
/// many there were in all, and a hint when the file looks like a
/// spreadsheet's export in another convention (`;` between cells, decimal
/// commas).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvErrors {
    /// The first errors, in file order.
    pub errors: Vec<CellError>,
    /// Errors found in all (at least `errors.len()`).
    pub total: usize,
    /// What probably caused them, when the file says so.
    pub hint: Option<String>,
}

impl CsvErrors {
    fn one(e: CellError, hint: Option<String>) -> Self {
        CsvErrors {
            errors: vec![e],
            total: 1,
            hint,
        }
    }

    /// "3 error(s)" or "120 error(s), the first 50 shown".
    pub fn count_text(&self) -> String {
        if self.total > self.errors.len() {
            format!(
                "{} error(s), the first {} shown",
                self.total,
                self.errors.len()
            )
        } else {
            format!("{} error(s)", self.total)
        }
    }
}

/// The expected header for `n` axis columns.
fn header_names(n: usize) -> Vec<String> {
    FIXED
        .iter()
        .map(|s| s.to_string())
        .chain((1..=n).map(|k| format!("axis{k}")))
        .collect()
}

/// Whether `names` is a valid header; its axis count if so.
fn header_axes<S: AsRef<str>>(names: &[S]) -> Option<usize> {
    let n = names.len().checked_sub(FIXED.len())?;
    let ok = (1..=MAX_AXES).contains(&n)
        && names
            .iter()
            .zip(header_names(n))
            .all(|(a, b)| a.as_ref().trim() == b);
    ok.then_some(n)
}

/// A number written with a decimal comma: `0,30`, `-25,5`.
fn decimal_comma(cell: &str) -> bool {
    let c = cell.trim().trim_start_matches('-');
    match c.split_once(',') {
        Some((i, f)) => {
            !i.is_empty()
                && !f.is_empty()
                && i.bytes().all(|b| b.is_ascii_digit())
                && f.bytes().all(|b| b.is_ascii_digit())
        }
        None => false,
    }
}

const EXPORT_ADVICE: &str = "save the table as CSV with ',' between cells and '.' as the decimal point (LibreOffice: Save As, Text CSV, field delimiter ','; Excel: \"CSV (Comma delimited)\" with '.' as the decimal separator in its options)";

/// The hint for a header that is not ours: a file whose cells are
/// separated by `;` or tabs (a spreadsheet set to a European locale), and
/// whose numbers then often carry decimal commas.
fn separator_hint(text: &str) -> Option<String> {
    let first = text.lines().next().unwrap_or("");
    let (sep, name) = [(';', "';'"), ('\t', "tabs")]
        .into_iter()
        .find(|(sep, _)| header_axes(&first.split(*sep).collect::<Vec<_>>()).is_some())?;
    let comma = text.lines().enumerate().skip(1).find_map(|(i, l)| {
        l.split(sep)
            .find(|c| decimal_comma(c))
            .map(|c| (i + 1, c.trim().to_string()))
    });
    let mut h = format!(
        "the cells are separated by {name}, as a spreadsheet set to a European locale exports CSV"
    );
    if let Some((line, cell)) = comma {
        h.push_str(&format!(
            ", and numbers carry a decimal comma (line {line}: {cell:?}; write {:?})",
            cell.replace(',', ".")
        ));
    }
    h.push_str(&format!(": {EXPORT_ADVICE}"));
    Some(h)
}

/// The hint for a row with more cells than the header: decimal commas
/// split numbers in two.
fn comma_hint(line: u64, row: &csv::StringRecord, want: usize) -> Option<String> {
    if row.len() <= want {
        return None;
    }
    let cells: Vec<&str> = row.iter().collect();
    // Two neighbouring cells of digits: the two halves of "0,30".
    let split = cells.windows(2).any(|w| {
        let [a, b] = w else { return false };
        !a.is_empty()
            && a.trim_start_matches('-')
                .bytes()
                .all(|c| c.is_ascii_digit())
            && !b.is_empty()
            && b.bytes().all(|c| c.is_ascii_digit())
    });
    split.then(|| {
        format!(
            "line {line} has {} cells where the header has {want}: numbers written with a decimal comma (\"0,30\" for 0.30) are split in two; {EXPORT_ADVICE}",
            row.len()
        )
    })
}

/// Reads a whole CSV table for a write message whose records use `layout`.
/// Returns the records in file order, or what is wrong: every row is
/// checked; the first [`SHOWN_ERRORS`] errors are kept and all are
/// counted. A header only (no rows) is an empty table, not an error.
pub fn read(mut input: impl Read, layout: RecordLayout) -> Result<Vec<PositionRecord>, CsvErrors> {
    let mut bytes = Vec::new();
    input.read_to_end(&mut bytes).map_err(|e| {
        CsvErrors::one(
            CellError {
                line: 1,
                column: "-".into(),
                message: format!("cannot read it: {e}"),
            },
            None,
        )
    })?;
    // A spreadsheet's UTF-8 byte-order mark is not part of the header.
    let body = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    let text = String::from_utf8_lossy(body);
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(body);
    let mut errors = Vec::new();
    let mut total = 0usize;
    let mut hint = None;
    let mut out = Vec::new();
    let mut axes = 0usize;
    let mut seen: BTreeMap<u16, u64> = BTreeMap::new();
    let number_spec = FieldSpec::hex(layout.number_width.max(1));
    let mut push = |errors: &mut Vec<CellError>, e: CellError| {
        total += 1;
        if errors.len() < SHOWN_ERRORS {
            errors.push(e);
        }
    };
    for (i, row) in rdr.records().enumerate() {
        let line = row
            .as_ref()
            .ok()
            .and_then(|r| r.position())
            .map_or(i as u64 + 1, |p| p.line());
        let row = match row {
            Ok(r) => r,
            Err(e) => {
                push(
                    &mut errors,
                    CellError {
                        line,
                        column: "-".into(),
                        message: format!("not readable as CSV: {e}"),
                    },
                );
                break;
            }
        };
        if i == 0 {
            let names: Vec<&str> = row.iter().collect();
            match header_axes(&names) {
                Some(n) => axes = n,
                None => {
                    return Err(CsvErrors::one(
                        CellError {
                            line,
                            column: "header".into(),
                            message: format!(
                                "expected number,acceleration,deceleration,speed,axis1[,axis2…,axis8], found {:?}",
                                names.join(",")
                            ),
                        },
                        separator_hint(&text),
                    ))
                }
            }
            continue;
        }
        if row.iter().all(str::is_empty) {
            continue;
        }
        if row.len() != FIXED.len() + axes {
            if hint.is_none() {
                hint = comma_hint(line, &row, FIXED.len() + axes);
            }
            push(
                &mut errors,
                CellError {
                    line,
                    column: "-".into(),
                    message: format!(
                        "{} cell(s), the header has {}",
                        row.len(),
                        FIXED.len() + axes
                    ),
                },
            );
            continue;
        }
        let mut bad = |column: &str, message: String| {
            push(
                &mut errors,
                CellError {
                    line,
                    column: column.to_string(),
                    message,
                },
            )
        };
        let get = |k: usize| row.get(k).unwrap_or("");
        let number = cell(get(0), number_spec, 0, "");
        let acc = cell(get(1), ACC, 2, "G");
        let dec = cell(get(2), ACC, 2, "G");
        let speed = cell(get(3), ACC, 0, "mm/s");
        let mut rec = PositionRecord::default();
        let mut ok = true;
        if let Ok(n) = number {
            if let Some(first) = seen.insert(n as u16, line) {
                bad("number", format!("position {n} is also on line {first}"));
                ok = false;
            }
        }
        for (col, r, slot) in [
            ("number", number, &mut rec.number),
            ("acceleration", acc, &mut rec.acceleration),
            ("deceleration", dec, &mut rec.deceleration),
            ("speed", speed, &mut rec.speed),
        ] {
            match r {
                Ok(v) => *slot = v as u16,
                Err(m) => {
                    bad(col, m);
                    ok = false;
                }
            }
        }
        let mut pattern = AxisPattern::NONE;
        let mut positions = PerAxis::new();
        for k in 1..=axes {
            let raw = get(FIXED.len() + k - 1);
            if raw.is_empty() {
                continue;
            }
            match cell(raw, COORD, 3, "mm") {
                Ok(v) => {
                    pattern = pattern.with(k as u8).unwrap_or(pattern);
                    let _ = positions.push(v as i32);
                }
                Err(m) => {
                    bad(&format!("axis{k}"), m);
                    ok = false;
                }
            }
        }
        if ok {
            rec.axes = pattern;
            rec.positions = positions;
            out.push(rec);
        }
    }
    if axes == 0 && errors.is_empty() {
        return Err(CsvErrors::one(
            CellError {
                line: 1,
                column: "header".into(),
                message:
                    "the file is empty; expected number,acceleration,deceleration,speed,axis1…"
                        .into(),
            },
            None,
        ));
    }
    if errors.is_empty() {
        Ok(out)
    } else {
        Err(CsvErrors {
            errors,
            total,
            hint,
        })
    }
}

/// Writes the header for `axes` axis columns.
pub fn write_header(out: &mut impl Write, axes: usize) -> std::io::Result<()> {
    let mut cols: Vec<String> = FIXED.iter().map(|s| s.to_string()).collect();
    cols.extend((1..=axes).map(|k| format!("axis{k}")));
    writeln!(out, "{}", cols.join(","))
}

/// Writes one record as a CSV row with `axes` axis columns (axes of the
/// record beyond them are not written: choose `axes` from the table).
pub fn write_row(out: &mut impl Write, rec: &PositionRecord, axes: usize) -> std::io::Result<()> {
    let mut cols = vec![
        rec.number.to_string(),
        format_scaled(i64::from(rec.acceleration), 2),
        format_scaled(i64::from(rec.deceleration), 2),
        rec.speed.to_string(),
    ];
    for k in 1..=axes as u8 {
        cols.push(
            rec.position(k)
                .map(|p| format_scaled(i64::from(p), 3))
                .unwrap_or_default(),
        );
    }
    writeln!(out, "{}", cols.join(","))
}

/// The highest axis any record uses (at least 1).
pub fn axes_used<'a>(recs: impl IntoIterator<Item = &'a PositionRecord>) -> usize {
    recs.into_iter()
        .flat_map(|r| r.axes.iter())
        .max()
        .map_or(1, usize::from)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn scaled_numbers_are_strict() {
        assert_eq!(parse_scaled("-12.3", 3), Ok(-12_300));
        assert_eq!(parse_scaled("0.30", 2), Ok(30));
        assert_eq!(parse_scaled("7", 3), Ok(7_000));
        for bad in [
            "", "-", "--1", "+1", "1.", ".5", "1.2345", "1_0", "1e3", " 1", "0x10",
        ] {
            assert!(parse_scaled(bad, 3).is_err(), "{bad:?}");
        }
        assert_eq!(format_scaled(-25_500, 3), "-25.500");
        assert_eq!(format_scaled(-5, 3), "-0.005");
        assert_eq!(format_scaled(30, 2), "0.30");
    }

    #[test]
    fn a_table_reads_and_writes_back_identically() {
        let text = "number,acceleration,deceleration,speed,axis1,axis2,axis3\n\
                    1,0.30,0.30,100,100.000,-25.500,\n\
                    2,0.00,0.00,0,,,-0.005\n";
        let recs = read(text.as_bytes(), RecordLayout::NUMBER_4).unwrap();
        assert_eq!(recs.len(), 2);
        assert_eq!(recs[0].positions.as_slice(), &[100_000, -25_500]);
        assert_eq!(recs[1].axes.bits(), 0b100);
        let mut out = Vec::new();
        write_header(&mut out, 3).unwrap();
        for r in &recs {
            write_row(&mut out, r, 3).unwrap();
        }
        assert_eq!(String::from_utf8(out).unwrap(), text);
    }

    #[test]
    fn every_bad_cell_is_named_with_its_range() {
        let text = "number,acceleration,deceleration,speed,axis1\n\
                    1,0.301,0.30,100,1.0\n\
                    70000,0.30,0.30,100,1\n\
                    3,0.30,0.30,-1,3000000\n\
                    1,0.30,0.30,1,1\n";
        let errs = read(text.as_bytes(), RecordLayout::NUMBER_4).unwrap_err();
        assert_eq!(errs.total, 5);
        let shown: Vec<String> = errs.errors.iter().map(|e| e.to_string()).collect();
        assert_eq!(shown.len(), 5, "{shown:#?}");
        assert!(
            shown[0].starts_with("line 2, column acceleration:"),
            "{}",
            shown[0]
        );
        assert!(shown[0].contains("0.00..=655.35 G"), "{}", shown[0]);
        assert!(shown[1].contains("line 3, column number") && shown[1].contains("0..=65535"));
        assert!(shown[2].contains("column speed"));
        assert!(
            shown[3].contains("column axis1") && shown[3].contains("-2147483.648..=2147483.647 mm")
        );
        assert!(shown[4].contains("also on line 2"), "{}", shown[4]);
        let errs = read("number,speed\n".as_bytes(), RecordLayout::NUMBER_4).unwrap_err();
        assert_eq!(errs.errors[0].column, "header");
        assert_eq!(errs.hint, None);
    }

    #[test]
    fn every_error_is_counted_and_the_first_50_are_shown() {
        let mut text = String::from("number,acceleration,deceleration,speed,axis1\n");
        for i in 0..120 {
            text.push_str(&format!("{i},0.301,0.30,100,1.000\n"));
        }
        let errs = read(text.as_bytes(), RecordLayout::NUMBER_4).unwrap_err();
        assert_eq!(errs.total, 120);
        assert_eq!(errs.errors.len(), SHOWN_ERRORS);
        assert_eq!(errs.count_text(), "120 error(s), the first 50 shown");
    }

    #[test]
    fn a_european_export_gets_a_hint_not_a_bare_header_error() {
        let text = "number;acceleration;deceleration;speed;axis1\n1;0,30;0,30;100;12,5\n";
        let errs = read(text.as_bytes(), RecordLayout::NUMBER_4).unwrap_err();
        let hint = errs.hint.unwrap();
        assert!(hint.contains("separated by ';'"), "{hint}");
        assert!(hint.contains("line 2: \"0,30\"; write \"0.30\""), "{hint}");
        let tabs = "number\tacceleration\tdeceleration\tspeed\taxis1\n";
        let hint = read(tabs.as_bytes(), RecordLayout::NUMBER_4)
            .unwrap_err()
            .hint
            .unwrap();
        assert!(hint.contains("separated by tabs"), "{hint}");
        // Decimal commas in a ','-separated file: more cells than the header.
        let text = "number,acceleration,deceleration,speed,axis1\n1,0,30,0.30,100,12.500\n";
        let errs = read(text.as_bytes(), RecordLayout::NUMBER_4).unwrap_err();
        let hint = errs.hint.unwrap();
        assert!(
            hint.contains("line 2 has 6 cells where the header has 5"),
            "{hint}"
        );
        // A byte-order mark is not part of the header.
        let bom = "\u{feff}number,acceleration,deceleration,speed,axis1\n1,0.30,0.30,100,1.000\n";
        assert_eq!(
            read(bom.as_bytes(), RecordLayout::NUMBER_4).unwrap().len(),
            1
        );
    }

    #[test]
    fn a_header_alone_is_an_empty_table() {
        let text = "number,acceleration,deceleration,speed,axis1\n";
        assert_eq!(
            read(text.as_bytes(), RecordLayout::NUMBER_4).unwrap(),
            vec![]
        );
    }
}
