//! End-to-end check of the example firmware under QEMU: bytes written on one
//! serial port come out unchanged on the other, both ways, and the quit
//! sequence ends the run with exit code 0.
//!
//! Needs `qemu-system-arm` and the `thumbv7m-none-eabi` /
//! `thumbv7em-none-eabihf` rustup targets.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::thread;
use std::time::{Duration, Instant};

use host_tests::qemu::{build_firmware, Board, QemuSession, QUIT_SEQUENCE};

/// Bytes sent per direction.
const LEN: usize = 4096;

/// Deterministic test bytes covering all values except the quit sequence's
/// ESC, so the data can never be mistaken for a quit request.
fn pattern(len: usize, seed: u32) -> Vec<u8> {
    let mut state = seed;
    (0..len)
        .map(|_| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            match (state >> 24) as u8 {
                b if b == QUIT_SEQUENCE[0] => b ^ 0x80,
                b => b,
            }
        })
        .collect()
}

/// Write `data` into `from` on a helper thread while reading the same number
/// of bytes from `to`; return what was read.
fn transfer(from: &TcpStream, to: &mut TcpStream, data: &[u8]) -> Vec<u8> {
    let mut writer = from.try_clone().expect("clone stream");
    let owned = data.to_vec();
    let handle = thread::spawn(move || {
        // Small chunks, like a serial line would deliver them.
        for chunk in owned.chunks(256) {
            writer.write_all(chunk)?;
        }
        writer.flush()
    });
    let mut received = vec![0; data.len()];
    let read = to.read_exact(&mut received);
    handle.join().expect("writer thread").expect("write");
    read.unwrap_or_else(|e| panic!("reading {} bytes: {e}", data.len()));
    received
}

#[test]
fn lm3s6965_passes_bytes_both_ways_and_quits() {
    let started = Instant::now();
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let mut qemu =
        QemuSession::start(Board::Lm3s6965, &elf, Duration::from_secs(10)).expect("start QEMU");

    let to_controller = pattern(LEN, 1);
    let received = transfer(&qemu.upstream, &mut qemu.downstream, &to_controller);
    assert!(
        received == to_controller,
        "upstream -> downstream corrupted"
    );

    let to_host = pattern(LEN, 2);
    let received = transfer(&qemu.downstream, &mut qemu.upstream, &to_host);
    assert!(received == to_host, "downstream -> upstream corrupted");

    // Both directions at once.
    let down_data = pattern(LEN, 3);
    let up_data = pattern(LEN, 4);
    let mut downstream = qemu.downstream.try_clone().expect("clone downstream");
    let upstream = qemu.upstream.try_clone().expect("clone upstream");
    let reverse = {
        let up_data = up_data.clone();
        let mut upstream_reader = qemu.upstream.try_clone().expect("clone upstream");
        let downstream_writer = qemu.downstream.try_clone().expect("clone downstream");
        thread::spawn(move || transfer(&downstream_writer, &mut upstream_reader, &up_data))
    };
    let received_down = transfer(&upstream, &mut downstream, &down_data);
    let received_up = reverse.join().expect("reverse transfer");
    assert!(
        received_down == down_data,
        "concurrent upstream -> downstream corrupted"
    );
    assert!(
        received_up == up_data,
        "concurrent downstream -> upstream corrupted"
    );

    qemu.quit().expect("send quit sequence");
    let outcome = qemu.wait(Duration::from_secs(5)).expect("QEMU exits");
    assert!(
        outcome.success(),
        "firmware did not exit cleanly: {outcome:#?}"
    );
    assert!(
        outcome.stdout.contains("bridge up on lm3s6965evb"),
        "missing banner: {outcome:#?}"
    );
    eprintln!("lm3s6965 passthrough took {:?}", started.elapsed());
}

#[test]
fn mps2_an386_firmware_builds_and_links() {
    let elf = build_firmware(Board::Mps2An386).expect("build mps2-an386 firmware");
    let bytes = std::fs::read(&elf).expect("read ELF");
    assert!(
        bytes.starts_with(b"\x7fELF"),
        "{} is not an ELF file",
        elf.display()
    );
    // e_machine (offset 18, little-endian) must be EM_ARM (40).
    assert_eq!(
        u16::from_le_bytes([bytes[18], bytes[19]]),
        40,
        "not an ARM ELF"
    );
}
