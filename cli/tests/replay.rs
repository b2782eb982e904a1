//! `iai inspect` over captures where a 216H reply is cut short and the
//! text it still expects swallows the frames that follow. The frame
//! decoder decodes a failed text frame's bytes again from its first header
//! byte; every frame it gives back is listed at its own offset, whether
//! the capture ends inside the 216H's text, goes on past it, or the text
//! ends inside one of those frames. Raw captures and text logs, JSON and
//! text listings.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{fixture_file, iai, stdout, temp};

/// `body` with its checksum and CR LF.
fn frame(body: &str) -> Vec<u8> {
    let sum = body.bytes().fold(0u8, |s, b| s.wrapping_add(b));
    format!("{body}{sum:02X}\r\n").into_bytes()
}

/// A 216H reply (error 0A1H, detail 1 = program 3) cut 3 characters into
/// a message whose length `count` announces.
fn cut_216h(count: u8) -> Vec<u8> {
    let mut f = format!("#992160A100000003{}", "00000000".repeat(7));
    f.push_str(&"0".repeat(15));
    f.push_str(&format!("{count:02X}Ser"));
    f.into_bytes()
}

/// 21 commands of 12 bytes each (212H, 213H, 253H, 254H in turn): the
/// 252 characters a 255-character message still expects after 3.
fn commands() -> Vec<Vec<u8>> {
    let bodies = ["!9921203", "!9921301", "!9925301", "!9925401"];
    (0..21).map(|i| frame(bodies[i % bodies.len()])).collect()
}

/// The message ID of a frame, as the JSON listing gives it.
fn id(frame: &[u8]) -> &str {
    std::str::from_utf8(&frame[3..6]).unwrap()
}

/// An entry of a JSON listing: offset, length, and `frame ID` or
/// `error KIND`; plus line and direction (text logs).
type Entry = (u64, u64, String, Option<(u64, String)>);

/// A listing as expected: offset, length, `frame ID` or `error KIND`.
type Want = Vec<(u64, u64, String)>;

fn listing(capture: &[u8], format: &str, name: &str) -> (Vec<Entry>, Option<i32>) {
    let path = temp(name, capture);
    let out = iai(&[
        "inspect",
        "--json",
        "--format",
        format,
        path.to_str().unwrap(),
    ]);
    let entries = stdout(&out)
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            let what = match v["type"].as_str().unwrap() {
                "frame" => format!("frame {}", v["id"].as_str().unwrap()),
                _ => format!("error {}", v["error"].as_str().unwrap()),
            };
            let from = v["line"]
                .as_u64()
                .map(|n| (n, v["dir"].as_str().unwrap_or("").to_string()));
            (
                v["offset"].as_u64().unwrap(),
                v["len"].as_u64().unwrap(),
                what,
                from,
            )
        })
        .collect();
    (entries, out.status.code())
}

/// The capture of one case, and the listing it must give: the 216H's
/// bytes before the first command as one error, then every frame at its
/// offset.
fn case(count: u8, tail: &[Vec<u8>], error: &str) -> (Vec<u8>, Want) {
    let mut cap = cut_216h(count);
    let mut want = vec![(0, cap.len() as u64, format!("error {error}"))];
    for f in commands().iter().chain(tail) {
        want.push((cap.len() as u64, f.len() as u64, format!("frame {}", id(f))));
        cap.extend_from_slice(f);
    }
    (cap, want)
}

/// The three captures: the capture ends inside the 216H's text; it goes
/// on past the text with a reply and a command; the text (32 characters)
/// ends inside the third command.
fn cases() -> Vec<(&'static str, Vec<u8>, Want)> {
    let (a, wa) = case(0xFF, &[], "Truncated");
    let (b, wb) = case(0xFF, &[frame("#99232"), frame("!9921203")], "Truncated");
    let (c, wc) = case(0x20, &[], "ChecksumMismatch");
    vec![
        ("ends-in-text", a, wa),
        ("goes-on", b, wb),
        ("text-ends-early", c, wc),
    ]
}

#[test]
fn every_frame_a_cut_216h_swallowed_is_listed_at_its_offset() {
    for (name, cap, want) in cases() {
        let (got, code) = listing(&cap, "raw", &format!("{name}.bin"));
        let got: Vec<_> = got.into_iter().map(|(o, l, w, _)| (o, l, w)).collect();
        assert_eq!(got, want, "{name}");
        assert_eq!(code, Some(1), "{name}: the cut 216H is an error");
    }
}

#[test]
fn the_same_from_a_text_log_line() {
    for (name, cap, want) in cases() {
        // The whole capture on one line, then a command on the next.
        let query = frame("!9921203");
        let log = format!(
            "< {}\n> {}\n",
            fixture_file::escape(&cap),
            fixture_file::escape(&query)
        );
        let (got, _) = listing(log.as_bytes(), "text", &format!("{name}.log"));
        let mut want: Vec<Entry> = want
            .into_iter()
            .map(|(o, l, w)| (o, l, w, Some((1, "rx".to_string()))))
            .collect();
        want.push((
            cap.len() as u64,
            query.len() as u64,
            "frame 212".into(),
            Some((2, "tx".into())),
        ));
        assert_eq!(got, want, "{name}");
    }
}

#[test]
fn the_text_listing_places_them_too() {
    let (_, cap, _) = cases().swap_remove(0);
    let path = temp("ends-in-text-listing.bin", &cap);
    let out = iai(&["inspect", "--format", "raw", path.to_str().unwrap()]);
    let text = stdout(&out);
    let first = text.lines().next().unwrap();
    assert!(
        first.starts_with("0x00000000  ERROR    Truncated: frame cut short by the end of the capture after 345 bytes, decoded again from offset 93  [93 bytes]"),
        "{text}"
    );
    for (i, f) in commands().iter().enumerate() {
        let at = format!("0x{:08X}  command  st 99  {}H ", 93 + 12 * i, id(f));
        assert!(text.contains(&at), "{at}: {text}");
    }
    assert!(text.ends_with("-- 21 frame(s), 1 error(s)\n"), "{text}");
}

/// Captures of cut and whole frames (200H and 216H text among them),
/// noise and a position stream, in any order: the entries tile the
/// capture, each byte in exactly one, whichever way it is split into
/// reads.
#[test]
fn the_entries_tile_any_capture() {
    use iai_cli::inspect::Inspector;
    let pieces: Vec<Vec<u8>> = vec![
        cut_216h(0xFF),
        cut_216h(0x04),
        frame("!99200HELLOWORLD"),
        b"!99200HEL#99".to_vec(),
        frame("!9921203"),
        frame("#99232"),
        b"#99232".to_vec(),
        b"\x00noise\r".to_vec(),
        b"\n".to_vec(),
        frame("!9926D0001000101001E001E0064000186A0"),
        frame("!9926D0001000103001E001E0064000186A0"),
        b"!9926D0002".to_vec(),
    ];
    let mut x = 0x2545_F491_u32;
    let mut next = move |n: usize| {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x as usize % n
    };
    for round in 0..300 {
        let mut cap = Vec::new();
        for _ in 0..1 + next(12) {
            cap.extend_from_slice(&pieces[next(pieces.len())]);
        }
        let list = |reads: &mut dyn FnMut() -> usize| {
            let mut ins = Inspector::new();
            let mut rest = &cap[..];
            while !rest.is_empty() {
                let n = (1 + reads()).min(rest.len());
                ins.feed(&rest[..n]);
                rest = &rest[n..];
            }
            ins.finish();
            ins.take_items()
                .into_iter()
                .map(|i| (i.offset, i.len, i.is_error()))
                .collect::<Vec<_>>()
        };
        let whole = list(&mut || usize::MAX - 1);
        let mut at = 0;
        for &(offset, len, _) in &whole {
            assert_eq!(
                offset,
                at,
                "round {round}: {whole:?}\n{}",
                fixture_file::escape(&cap)
            );
            at += len;
        }
        assert_eq!(at, cap.len() as u64, "round {round}: {whole:?}");
        assert_eq!(list(&mut || next(7)), whole, "round {round}");
    }
}
