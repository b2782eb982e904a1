//! The async flavour of the transfer engine (feature `async`), over an
//! in-memory `embedded-io-async` UART wired to the simulator on a virtual
//! clock, driven by a minimal executor.

use std::cell::Cell;
use std::collections::VecDeque;
use std::future::Future;
use std::pin::pin;
use std::rc::Rc;
use std::task::{Context, Poll, Waker};

use host_tests::table::table;
use iai_protocol_b::clock::AsyncClock;
use iai_protocol_b::frame::Station;
use iai_protocol_b::transfer::{Guarantee, Transfer, TransferConfig};
use iai_protocol_b::{line::Line, line::LineConfig, profile::Profile};
use iai_simulator::{Faults, Simulator};

struct SimUart {
    sim: Simulator,
    now: Rc<Cell<u32>>,
    inbox: VecDeque<u8>,
}

impl embedded_io_async::ErrorType for SimUart {
    type Error = std::convert::Infallible;
}
impl embedded_io_async::ReadReady for SimUart {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        self.inbox.extend(self.sim.take_output(self.now.get()));
        Ok(!self.inbox.is_empty())
    }
}
impl embedded_io_async::Read for SimUart {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let n = buf.len().min(self.inbox.len());
        for (slot, b) in buf.iter_mut().zip(self.inbox.drain(..n)) {
            *slot = b;
        }
        Ok(n)
    }
}
impl embedded_io_async::Write for SimUart {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        self.sim.receive(buf, self.now.get());
        Ok(buf.len())
    }
    async fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

struct VirtualClock(Rc<Cell<u32>>);
impl AsyncClock for VirtualClock {
    fn now_ms(&mut self) -> u32 {
        self.0.get()
    }
    async fn sleep_ms(&mut self, ms: u32) {
        self.0.set(self.0.get() + ms);
    }
}

fn block_on<F: Future>(f: F) -> F::Output {
    let mut f = pin!(f);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(v) = f.as_mut().poll(&mut cx) {
            return v;
        }
    }
}

#[test]
fn async_transfer_with_faults_writes_the_whole_table() {
    let now = Rc::new(Cell::new(0));
    let faults = Faults {
        flip_bit_in: 1e-4,
        drop_every_nth_reply: Some(50),
        error_reply: 0.01,
        ..Faults::default()
    };
    let mut uart = SimUart {
        sim: Simulator::tta(Station(0x99)).with_faults(faults, 5),
        now: now.clone(),
        inbox: VecDeque::new(),
    };
    let mut clock = VirtualClock(now);
    let mut t: Transfer<_> = Transfer::new(TransferConfig::new(Profile::TTA), table(5_000, 8, 8));
    let mut line = Line::new(LineConfig::new(Station(0x99)), 3);
    // A chunk can fail three times in a row under this fault mix, and an
    // error reply stops the transfer: the documented answer is to resume,
    // which sends the same chunk again.
    let mut resumes = 0;
    let guarantee = loop {
        match block_on(t.run_async(&mut line, &mut uart, &mut clock, 10)) {
            Ok(g) => break g,
            Err(e) if resumes < 200 => {
                println!("resuming after {e:?}");
                resumes += 1;
                t.resume(&mut line, clock.now_ms());
            }
            Err(e) => panic!("{e:?}"),
        }
    };
    assert_eq!(guarantee, Guarantee::Verified);
    assert_eq!(t.stats().records_confirmed, 5_000);
    assert!(t.stats().retries > 0);
    let expected: std::collections::BTreeMap<_, _> =
        table(5_000, 8, 8).map(|r| (r.number, r)).collect();
    assert!(uart.sim.table == expected);
}

#[test]
fn async_client_gets_its_typed_reply_through_a_lossy_line() {
    use iai_protocol_b::client::Client;
    use iai_protocol_b::message::AxisStatusQuery;
    let now = Rc::new(Cell::new(0));
    let faults = Faults {
        drop_every_nth_reply: Some(2),
        ..Faults::default()
    };
    let mut uart = SimUart {
        sim: Simulator::tta(Station(0x99)).with_faults(faults, 6),
        now: now.clone(),
        inbox: VecDeque::new(),
    };
    let mut clock = VirtualClock(now);
    let mut client: Client = Client::new();
    let mut line = Line::new(LineConfig::new(Station(0x99)), 4);
    let q = AxisStatusQuery::of(&[1, 2]).unwrap();
    for _ in 0..4 {
        let reply = block_on(client.call_async(&mut line, &mut uart, &mut clock, 10, &q)).unwrap();
        assert_eq!(reply.axes.len(), 2);
    }
    // Every second reply is dropped. The opening fence's echo comes (reply
    // 1); request 1's reply is dropped (2), its resend answered (3); the
    // dropped reply is owed, so request 2 is fenced: that echo is dropped
    // (4), the fence times out and a second fence is answered (5); request
    // 2's reply is dropped (6), its resend answered (7); requests 3 and 4
    // go as request 2: seven fences, three of them failed, four resends,
    // each lost frame costing its 3 s.
    let s = line.stats();
    assert_eq!((s.resends, s.fences, s.fences_failed), (4, 7, 3));
    assert!(clock.now_ms() >= 7 * 3_000);
}
