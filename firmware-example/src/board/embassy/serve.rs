//! The bridge's loops as embassy tasks run them: the library's own loops
//! (`crate::bridge::run`, `crate::modbus::run`, `crate::modbus::run_one_upstream`)
//! take a function that sleeps; here the loop awaits instead, until a
//! line's task moved bytes ([`super::line::serve`] signals `moved`) or the
//! next millisecond (the bridge's timers count milliseconds). Each pass
//! makes the same calls in the same order as the library's loops.

use core::convert::Infallible;

use embassy_futures::select::select;
use embassy_futures::yield_now;
use embassy_time::Timer;

use super::line::Wake;
use crate::board::clock::{now_ms, now_us};
use crate::bridge::{Bridge, Error, NoPort, Poll};
use crate::config::UpstreamProtocol;
use crate::modbus::Gateway;
use crate::serial::Port;
use crate::status::Stats;

/// Waits until a line moved bytes or a millisecond passed.
async fn idle(moved: &Wake) {
    select(moved.wait(), Timer::after_millis(1)).await;
}

/// The bridge over its two lines until the host's quit sequence (`Ok` with
/// the counters), calling `feed` on every pass (the watchdog).
pub async fn bridge<U: Port<Error = Infallible>, D: Port<Error = Infallible>>(
    bridge: &mut Bridge,
    up: &mut U,
    down: &mut D,
    moved: &Wake,
    mut feed: impl FnMut(),
) -> Result<Stats, Error<Infallible, Infallible>> {
    loop {
        feed();
        match bridge.poll(up, down, now_ms())? {
            Poll::Quit => return Ok(bridge.stats()),
            Poll::Busy => yield_now().await,
            Poll::Wait(_) => idle(moved).await,
        }
    }
}

/// [`bridge`] with the Modbus gateway on its own port beside it, as
/// [`crate::modbus::run`] runs them.
pub async fn gateway<U, D, M>(
    bridge: &mut Bridge,
    gateway: &mut Gateway,
    up: &mut U,
    down: &mut D,
    modbus: &mut M,
    moved: &Wake,
    mut feed: impl FnMut(),
) -> Result<Stats, Error<Infallible, Infallible>>
where
    U: Port<Error = Infallible>,
    D: Port<Error = Infallible>,
    M: Port<Error = Infallible>,
{
    loop {
        feed();
        let served = gateway
            .serve(modbus, now_ms(), now_us())
            .map_err(Error::Upstream)?;
        match bridge.poll_with(up, down, gateway, now_ms())? {
            Poll::Quit => return Ok(bridge.stats()),
            Poll::Busy => yield_now().await,
            Poll::Wait(_) if served => yield_now().await,
            Poll::Wait(_) => idle(moved).await,
        }
    }
}

/// One upstream port that speaks what the configuration chose, as
/// [`crate::modbus::run_one_upstream`] runs it: protocol B through the
/// bridge, or Modbus RTU through the gateway with no protocol-B host.
pub async fn one_upstream<U, D>(
    speaks: UpstreamProtocol,
    bridge: &mut Bridge,
    gateway: &mut Gateway,
    up: &mut U,
    down: &mut D,
    moved: &Wake,
    feed: impl FnMut(),
) -> Result<Stats, Error<Infallible, Infallible>>
where
    U: Port<Error = Infallible>,
    D: Port<Error = Infallible>,
{
    match speaks {
        UpstreamProtocol::ProtocolB => self::bridge(bridge, up, down, moved, feed).await,
        UpstreamProtocol::ModbusRtu => {
            self::gateway(bridge, gateway, &mut NoPort, down, up, moved, feed).await
        }
    }
}
