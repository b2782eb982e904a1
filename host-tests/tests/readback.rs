//! Read-back: a table written through the transfer engine is read back in
//! windows with 21FH and compared with the source.

use host_tests::link::run;
use host_tests::sim::{Faults, Simulator};
use host_tests::table::table;
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::readback::{ReadBack, ReadBackConfig, ReadBackStats};
use iai_protocol_b::transfer::{Transfer, TransferConfig, TransferError};

const ST: Station = Station(0x99);

/// Drives a read-back against the simulator on a virtual clock.
fn read_back(
    rb: &mut ReadBack,
    sim: &mut Simulator,
) -> (Vec<PositionRecord>, Result<ReadBackStats, TransferError>) {
    let r = host_tests::link::read_back(rb, sim);
    (r.records, r.result)
}

#[test]
fn a_written_table_reads_back_equal() {
    let mut sim = Simulator::tta(ST);
    let mut t: Transfer<_> = Transfer::new(TransferConfig::tta(ST), table(2_000, 8, 31));
    run(&mut t, &mut sim, 0).result.unwrap();
    let mut rb: ReadBack = ReadBack::new(ReadBackConfig::tta(ST, 1, 2_000));
    assert_eq!(
        ReadBackConfig::tta(ST, 1, 2_000).window(),
        24,
        "24 records of 82 bytes fit 2,048"
    );
    let (got, stats) = read_back(&mut rb, &mut sim);
    let stats = stats.unwrap();
    assert_eq!(got, table(2_000, 8, 31).collect::<Vec<_>>());
    assert_eq!(stats.queries, 2_000u32.div_ceil(24));
}

#[test]
fn read_back_of_a_sparse_table_with_faults_skips_nothing() {
    let mut sim = Simulator::tta(ST).with_faults(
        Faults {
            flip_bit_out: 1.0 / 5_000.0,
            drop_every_nth_reply: Some(7),
            ..Faults::default()
        },
        9,
    );
    // Every third position defined, 1 to 4 axes.
    let recs: Vec<_> = (0..600u32)
        .map(|i| {
            let mut r = host_tests::table::record(i, (i % 4 + 1) as u8, 5);
            r.number = (i * 3 + 1) as u16;
            r
        })
        .collect();
    for r in &recs {
        sim.table.insert(r.number, r.clone());
    }
    let mut rb: ReadBack = ReadBack::new(ReadBackConfig::tta(ST, 1, 1_800));
    let (got, stats) = read_back(&mut rb, &mut sim);
    let stats = stats.unwrap();
    assert_eq!(got, recs);
    assert!(stats.retries > 0 && stats.timeouts > 0);
}
