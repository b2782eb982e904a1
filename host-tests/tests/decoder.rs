//! The push decoder against whole streams: every fixture frame back to back,
//! cut into chunks every possible way, and random bytes with valid frames
//! spliced in. The decoder must give the same events however the input is
//! cut, never panic, only ever return valid frames, and account for every
//! byte it was given.

#[path = "../fixtures/fixture_file.rs"]
mod fixture_file;
mod replay;

use replay::{decode_chunks, push_bytes, Out};

use iai_protocol_b::checksum::{BypassPolicy, Checksum, ChecksumField};
use iai_protocol_b::decoder::{Event, FrameDecoder, Status, DEFAULT_CAPACITY};
use iai_protocol_b::error::Error;
use iai_protocol_b::frame::Frame;
use proptest::prelude::*;
use test_support::reference_decoder::{Reference, ReferenceDecoder};

/// Small deterministic generator (SplitMix64), so failures reproduce.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `0..n` (n > 0).
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn byte(&mut self) -> u8 {
        self.next() as u8
    }
}

/// Every byte given to the decoder is in a returned frame, counted as
/// discarded, or pending; the counters match the events.
fn assert_accounted<const N: usize>(dec: &FrameDecoder<N>, input_len: usize, events: &[Out]) {
    let s = dec.stats();
    let frames: Vec<&Vec<u8>> = events
        .iter()
        .filter_map(|e| match e {
            Out::Frame(f) => Some(f),
            Out::Error(_) => None,
        })
        .collect();
    let errors = events.len() - frames.len();
    assert_eq!(s.frames as usize, frames.len(), "stats.frames");
    assert_eq!(s.errors as usize, errors, "stats.errors");
    let in_frames: usize = frames.iter().map(|f| f.len()).sum();
    assert!(s.discarded_bytes as usize <= input_len);
    assert_eq!(
        in_frames + s.discarded_bytes as usize + dec.pending(),
        input_len,
        "frame bytes + discarded + pending must equal the input"
    );
}

/// A returned frame is valid by itself, and its checksum is right (or an
/// `@@` the policy allows).
fn assert_valid_frame(bytes: &[u8], policy: BypassPolicy) {
    let f = Frame::new_checked(bytes, policy)
        .unwrap_or_else(|e| panic!("decoder returned an invalid frame {bytes:?}: {e}"));
    let sc_at = bytes.len() - 4;
    match f.checksum() {
        ChecksumField::Sum(sc) => assert_eq!(sc, Checksum::of(&bytes[..sc_at])),
        ChecksumField::Bypass => {
            assert_eq!(&bytes[sc_at..sc_at + 2], b"@@");
            assert!(policy.allows(f.header()));
        }
    }
    assert!(bytes.ends_with(b"\r\n"));
}

fn fixture_frames() -> (Vec<u8>, Vec<Out>) {
    let (stream, frames) = fixture_file::stream();
    (stream, frames.into_iter().map(Out::Frame).collect())
}

// ---------------------------------------------------------------------------
// The fixture stream.

#[test]
fn fixture_stream_in_one_call_gives_every_frame_in_order() {
    let (stream, expected) = fixture_frames();
    let mut dec: FrameDecoder = FrameDecoder::new();
    let got = decode_chunks(&mut dec, &stream, &[]);
    assert_eq!(got, expected);
    assert_eq!(dec.stats().discarded_bytes, 0);
    assert_eq!(dec.stats().errors, 0);
    assert_eq!(dec.pending(), 0);
    assert_accounted(&dec, stream.len(), &got);
}

#[test]
fn fixture_stream_split_in_two_at_every_byte_position() {
    let (stream, expected) = fixture_frames();
    for cut in 0..=stream.len() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let got = decode_chunks(&mut dec, &stream, &[cut]);
        assert_eq!(got, expected, "split at {cut}");
        assert_accounted(&dec, stream.len(), &got);
    }
}

#[test]
fn fixture_stream_in_random_chunk_sizes() {
    let (stream, expected) = fixture_frames();
    let mut rng = Rng(0x01A1_B003);
    for round in 0..300 {
        // Mostly small chunks, some large ones.
        let max = [1, 3, 8, 40, 300, stream.len()][round % 6];
        let cuts: Vec<usize> = (0..stream.len()).map(|_| rng.below(max) + 1).collect();
        let mut dec: FrameDecoder = FrameDecoder::new();
        let got = decode_chunks(&mut dec, &stream, &cuts);
        assert_eq!(got, expected, "round {round}");
        assert_accounted(&dec, stream.len(), &got);
    }
}

#[test]
fn fixture_stream_byte_by_byte_with_push() {
    let (stream, expected) = fixture_frames();
    let mut dec: FrameDecoder = FrameDecoder::new();
    let got = push_bytes(&mut dec, &stream);
    assert_eq!(got, expected);
    assert_accounted(&dec, stream.len(), &got);
}

#[test]
fn fixture_stream_with_header_free_noise_between_frames() {
    let (_, frames) = fixture_file::stream();
    let noise: &[&[u8]] = &[
        b"",
        b"\r\n",
        b"\n",
        b"xyz",
        b"\x00\xFF\x80",
        b"@@",
        b"\r\r\n  ",
    ];
    let mut stream = Vec::new();
    let mut noise_len = 0;
    for (i, f) in frames.iter().enumerate() {
        let n = noise[i % noise.len()];
        stream.extend_from_slice(n);
        noise_len += n.len();
        stream.extend_from_slice(f);
    }
    let expected: Vec<Out> = frames.into_iter().map(Out::Frame).collect();
    let mut dec: FrameDecoder = FrameDecoder::new();
    let got = push_bytes(&mut dec, &stream);
    assert_eq!(got, expected);
    assert_eq!(dec.stats().discarded_bytes as usize, noise_len);
    assert_eq!(dec.stats().errors, 0);
}

#[test]
fn fixture_stream_under_each_bypass_policy() {
    let (stream, frames) = fixture_file::stream();
    for policy in [
        BypassPolicy::Reject,
        BypassPolicy::CommandsOnly,
        BypassPolicy::Accept,
    ] {
        let expected: Vec<Out> = frames
            .iter()
            .map(|f| {
                let bypass = f[f.len() - 4..f.len() - 2] == *b"@@";
                if bypass && policy == BypassPolicy::Reject {
                    Out::Error(Error::ChecksumBypassRejected)
                } else {
                    Out::Frame(f.clone())
                }
            })
            .collect();
        let mut dec: FrameDecoder = FrameDecoder::with_policy(policy);
        assert_eq!(dec.policy(), policy);
        let got = decode_chunks(&mut dec, &stream, &[7; 1000]);
        assert_eq!(got, expected, "{policy:?}");
        assert_accounted(&dec, stream.len(), &got);
    }
}

#[test]
fn reset_drops_the_partial_frame_and_counts_it() {
    let mut dec: FrameDecoder = FrameDecoder::new();
    assert!(matches!(dec.decode(b"xx#99212").status, Status::Partial));
    assert_eq!(dec.pending(), 6);
    dec.reset();
    assert_eq!(dec.pending(), 0);
    assert_eq!(dec.stats().discarded_bytes, 8);
    let got = push_bytes(&mut dec, b"021C00000000002715AF\r\n#992322C\r\n");
    assert_eq!(got, vec![Out::Frame(b"#992322C\r\n".to_vec())]);
    assert_accounted(&dec, 8 + 22 + 10, &got);
}

// ---------------------------------------------------------------------------
// Random bytes.

/// Random bytes: half fully random, half from an alphabet rich in the
/// bytes the decoder reacts to (headers, hex digits, CR, LF, '@').
fn random_bytes(rng: &mut Rng, n: usize, out: &mut Vec<u8>) {
    const ALPHABET: &[u8] = b"!#&%0123456789ABCDEFabcdef@\r\n2169Z";
    let rich = rng.below(2) == 0;
    for _ in 0..n {
        if rich {
            out.push(ALPHABET[rng.below(ALPHABET.len())]);
        } else {
            out.push(rng.byte());
        }
    }
}

/// A separator that leaves the decoder hunting whatever came before it:
/// longer than any text field (216H: at most 255 raw characters), no header
/// byte, then CR LF to end a frame in progress.
fn separator(rng: &mut Rng, out: &mut Vec<u8>) {
    let n = 260 + rng.below(40);
    for _ in 0..n {
        let b = loop {
            let b = rng.byte();
            if !matches!(b, b'!' | b'#' | b'&' | b'%' | b'\r' | b'\n') {
                break b;
            }
        };
        out.push(b);
    }
    out.extend_from_slice(b"\r\n");
}

/// Runs one random case through decoders of capacity `N`; returns the
/// bytes processed.
fn random_case<const N: usize>(rng: &mut Rng, frames: &[Vec<u8>], policy: BypassPolicy) -> usize {
    let mut input = Vec::new();
    let mut spliced = Vec::new();
    for _ in 0..rng.below(12) + 1 {
        let len = rng.below(600);
        random_bytes(rng, len, &mut input);
        if rng.below(3) > 0 {
            separator(rng, &mut input);
            let f = &frames[rng.below(frames.len())];
            input.extend_from_slice(f);
            let allowed = f[f.len() - 4..f.len() - 2] != *b"@@" || policy.allows_byte(f[0]);
            if allowed && f.len() <= N {
                spliced.push(f.clone());
            }
        }
    }
    let max = [1, 2, 16, 100, 5000][rng.below(5)];
    let cuts: Vec<usize> = (0..input.len()).map(|_| rng.below(max) + 1).collect();

    let mut chunked: FrameDecoder<N> = FrameDecoder::with_policy(policy);
    let events = decode_chunks(&mut chunked, &input, &cuts);
    let mut pushed: FrameDecoder<N> = FrameDecoder::with_policy(policy);
    let by_byte = push_bytes(&mut pushed, &input);
    assert_eq!(events, by_byte, "events must not depend on chunking");
    assert_eq!(chunked.stats(), pushed.stats());
    assert_accounted(&chunked, input.len(), &events);

    let mut want = spliced.iter().peekable();
    for e in &events {
        match e {
            Out::Frame(f) => {
                assert_valid_frame(f, policy);
                assert!(f.len() <= N);
                if want.peek() == Some(&f) {
                    want.next();
                }
            }
            Out::Error(Error::FrameTooLong { limit }) => assert_eq!(*limit, N),
            Out::Error(_) => {}
        }
    }
    assert!(
        want.peek().is_none(),
        "spliced frame {:?} not found",
        want.peek().map(|f| String::from_utf8_lossy(f))
    );
    input.len()
}

trait AllowsByte {
    fn allows_byte(self, header: u8) -> bool;
}
impl AllowsByte for BypassPolicy {
    fn allows_byte(self, header: u8) -> bool {
        let h = iai_protocol_b::frame::Header::from_byte(header).unwrap();
        self.allows(h)
    }
}

#[test]
fn random_bytes_with_spliced_frames_never_break_the_decoder() {
    let (_, frames) = fixture_file::stream();
    let mut rng = Rng(0x5EED_0000_0000_0026);
    let policies = [
        BypassPolicy::Reject,
        BypassPolicy::CommandsOnly,
        BypassPolicy::Accept,
    ];
    let mut total = 0;
    let mut case = 0;
    // Each case is decoded twice (chunked and byte by byte).
    while total < 3_000_000 {
        let policy = policies[case % 3];
        total += match case % 4 {
            0 => random_case::<16>(&mut rng, &frames, policy),
            1 => random_case::<100>(&mut rng, &frames, policy),
            _ => random_case::<DEFAULT_CAPACITY>(&mut rng, &frames, policy),
        };
        case += 1;
    }
    eprintln!("{case} random cases, {total} bytes, each decoded twice");
}

#[test]
fn long_runs_without_a_frame_end_overflow_and_recover() {
    // A header followed by more bytes than the buffer holds.
    let mut rng = Rng(7);
    let mut input = vec![b'#'];
    for _ in 0..5000 {
        input.push(b"0123456789ABCDEF"[rng.below(16)]);
    }
    input.extend_from_slice(b"\r\n#992322C\r\n");
    let mut dec: FrameDecoder = FrameDecoder::new();
    let got = decode_chunks(&mut dec, &input, &[999; 10]);
    assert_eq!(
        got,
        vec![
            Out::Error(Error::FrameTooLong {
                limit: DEFAULT_CAPACITY
            }),
            Out::Frame(b"#992322C\r\n".to_vec())
        ]
    );
    assert_accounted(&dec, input.len(), &got);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Arbitrary bytes, then a separator, then a fixture frame, fed in
    /// arbitrary chunks: the frame comes out and every byte is accounted.
    #[test]
    fn arbitrary_prefix_then_fixture_frame(
        prefix in proptest::collection::vec(any::<u8>(), 0..400),
        pick in any::<prop::sample::Index>(),
        cuts in proptest::collection::vec(1usize..64, 0..64),
    ) {
        let (_, frames) = fixture_file::stream();
        let frame = pick.get(&frames).clone();
        let mut input = prefix;
        input.extend_from_slice(&[b'Z'; 300]);
        input.extend_from_slice(b"\r\n");
        input.extend_from_slice(&frame);
        let mut dec: FrameDecoder = FrameDecoder::new();
        let got = decode_chunks(&mut dec, &input, &cuts);
        prop_assert_eq!(got.last(), Some(&Out::Frame(frame)));
        for e in &got {
            if let Out::Frame(f) = e {
                assert_valid_frame(f, BypassPolicy::CommandsOnly);
            }
        }
        assert_accounted(&dec, input.len(), &got);
        prop_assert_eq!(dec.pending(), 0);
    }
}

// ---------------------------------------------------------------------------
// Size.

#[test]
fn decoder_size_at_the_default_capacity() {
    let default = core::mem::size_of::<FrameDecoder>();
    let small = core::mem::size_of::<FrameDecoder<64>>();
    eprintln!(
        "size_of::<FrameDecoder>() = {default} bytes (capacity {DEFAULT_CAPACITY}); \
         FrameDecoder<64> = {small} bytes"
    );
    assert!(default >= DEFAULT_CAPACITY);
    assert!(default < DEFAULT_CAPACITY + 96, "{default} bytes");
    assert!(small < 64 + 96);
    assert_eq!(FrameDecoder::<64>::new().capacity(), 64);
}

// ---------------------------------------------------------------------------
// Against the reference decoder.

/// `head` + its SC (upper or lower case) + CR LF.
fn with_trailer(head: &[u8], lower: bool) -> Vec<u8> {
    let sc = format!("{:02X}", Checksum::of(head));
    let sc = if lower { sc.to_lowercase() } else { sc };
    let mut f = head.to_vec();
    f.extend_from_slice(sc.as_bytes());
    f.extend_from_slice(b"\r\n");
    f
}

/// A frame, whole or damaged, of a kind the decoder treats apart: a
/// fixture frame, a 200H with ten raw characters (header bytes, CR, LF
/// among them), a 216H reply with a counted text, a long 26DH-like body, a
/// frame cut, a byte of it changed, its SC wrong.
fn reference_case_frame(rng: &mut Rng, fixtures: &[Vec<u8>], out: &mut Vec<u8>) {
    const TEXT: &[u8] = b"!#&%\r\n0123456789ABCDEFabcdef@xyz";
    let text = |rng: &mut Rng, n: usize| -> Vec<u8> {
        (0..n).map(|_| TEXT[rng.below(TEXT.len())]).collect()
    };
    let header = [b'!', b'#', b'&', b'%'][rng.below(4)];
    let mut frame = match rng.below(5) {
        0 => fixtures[rng.below(fixtures.len())].clone(),
        1 => {
            let mut head = vec![header];
            head.extend_from_slice(b"99200");
            head.extend(text(rng, 10));
            with_trailer(&head, rng.below(4) == 0)
        }
        2 => {
            // 216H reply: 82 digits, then the count and that many characters
            // (or fewer or more than counted).
            let n = rng.below(40);
            let mut head = vec![if rng.below(4) == 0 { header } else { b'#' }];
            head.extend_from_slice(b"99216");
            head.extend((0..82).map(|_| b"0123456789ABCDEF"[rng.below(16)]));
            head.extend_from_slice(format!("{n:02X}").as_bytes());
            let told = (n + rng.below(3)).saturating_sub(1);
            head.extend(text(rng, told.min(60)));
            with_trailer(&head, false)
        }
        3 => {
            let mut head = vec![header];
            head.extend_from_slice(if rng.below(2) == 0 {
                b"9926D"
            } else {
                b"99g6d"
            });
            let n = rng.below(2100);
            head.extend((0..n).map(|_| b"0123456789ABCDEFabcdef"[rng.below(22)]));
            with_trailer(&head, rng.below(2) == 0)
        }
        _ => {
            let n = rng.below(30);
            let mut head = vec![header];
            head.extend(text(rng, n));
            with_trailer(&head, false)
        }
    };
    match rng.below(6) {
        0 if !frame.is_empty() => frame.truncate(rng.below(frame.len())),
        1 if !frame.is_empty() => {
            let at = rng.below(frame.len());
            frame[at] = TEXT[rng.below(TEXT.len())];
        }
        2 if frame.len() >= 4 => {
            let at = frame.len() - 4;
            frame[at] ^= 1;
        }
        _ => {}
    }
    out.extend_from_slice(&frame);
}

/// The decoder's answer in the reference's terms; a frame must also be
/// what `Frame::new_checked` makes of its bytes.
fn as_reference(status: Status<Event<'_>>, policy: BypassPolicy) -> Reference {
    match status {
        Status::Partial => Reference::Partial,
        Status::Complete(Event::Frame(f)) => {
            assert_eq!(Frame::new_checked(f.as_bytes(), policy), Ok(f));
            Reference::Frame(f.as_bytes().to_vec())
        }
        Status::Complete(Event::Error(e)) => Reference::Error(e),
    }
}

/// Everything a caller can see of the two decoders is the same.
fn assert_same_as_reference<const N: usize>(dec: &FrameDecoder<N>, reference: &ReferenceDecoder) {
    assert_eq!(dec.stats(), reference.stats(), "stats");
    assert_eq!(dec.pending(), reference.pending(), "pending");
    assert_eq!(
        dec.failed_envelope(),
        reference.failed_envelope(),
        "failed envelope"
    );
    assert_eq!(
        dec.last_frame().map(|f| f.as_bytes()),
        reference.last_frame(),
        "last frame"
    );
}

/// Feeds `input` to a decoder and the reference in lockstep, in the
/// chunks `cuts` gives through `decode` (or byte by byte through `push`
/// where a cut is 0), with a `reset` of both now and then, comparing every
/// answer and everything visible after it.
fn lockstep<const N: usize>(rng: &mut Rng, input: &[u8], cuts: &[usize], policy: BypassPolicy) {
    let mut dec: FrameDecoder<N> = FrameDecoder::with_policy(policy);
    let mut reference = ReferenceDecoder::new(N, policy);
    let mut rest = input;
    let mut cuts = cuts.iter();
    while !rest.is_empty() {
        if rng.below(200) == 0 {
            dec.reset();
            reference.reset();
            assert_same_as_reference(&dec, &reference);
        }
        let n = cuts.next().copied().unwrap_or(rest.len()).min(rest.len());
        if n == 0 {
            let (&b, tail) = rest.split_first().unwrap();
            rest = tail;
            let want = reference.push(b);
            assert_eq!(as_reference(dec.push(b), policy), want);
            assert_same_as_reference(&dec, &reference);
            continue;
        }
        let mut chunk = &rest[..n];
        rest = &rest[n..];
        loop {
            let (used, want) = reference.decode(chunk);
            let d = dec.decode(chunk);
            assert_eq!(d.consumed, used, "consumed");
            let done = want == Reference::Partial;
            assert_eq!(as_reference(d.status, policy), want);
            assert_same_as_reference(&dec, &reference);
            chunk = &chunk[used..];
            if done && chunk.is_empty() {
                break;
            }
        }
    }
    loop {
        let (_, want) = reference.decode(&[]);
        assert_eq!(as_reference(dec.decode(&[]).status, policy), want);
        assert_same_as_reference(&dec, &reference);
        if want == Reference::Partial {
            break;
        }
    }
}

/// The decoder takes short cuts (plain body bytes stored without a step,
/// the text span looked for only where the message has one): over frames
/// of every kind, whole and damaged, between random bytes, in chunks of
/// every size and byte by byte, at four capacities, it gives what the
/// reference decoder gives, call for call.
#[test]
fn the_decoder_gives_what_the_reference_decoder_gives() {
    let (_, fixtures) = fixture_file::stream();
    let mut rng = Rng(0x0032_DEC0_DE00_0032);
    let policies = [
        BypassPolicy::Reject,
        BypassPolicy::CommandsOnly,
        BypassPolicy::Accept,
    ];
    let mut total = 0;
    let mut case = 0;
    while total < 4_000_000 {
        let mut input = Vec::new();
        for _ in 0..rng.below(10) + 1 {
            let noise = [0, 0, 1, 3, 40][rng.below(5)];
            random_bytes(&mut rng, noise, &mut input);
            reference_case_frame(&mut rng, &fixtures, &mut input);
        }
        let max = [1, 2, 16, 100, 5000][rng.below(5)];
        let cuts: Vec<usize> = (0..input.len()).map(|_| rng.below(max + 1)).collect();
        let policy = policies[case % 3];
        match case % 5 {
            0 => lockstep::<16>(&mut rng, &input, &cuts, policy),
            1 => lockstep::<100>(&mut rng, &input, &cuts, policy),
            2 => lockstep::<0>(&mut rng, &input, &cuts, policy),
            _ => lockstep::<DEFAULT_CAPACITY>(&mut rng, &input, &cuts, policy),
        }
        total += input.len();
        case += 1;
    }
    eprintln!("{case} cases, {total} bytes, every answer the reference's");
}
