//! Every write of the configuration page, and the restart, behind the
//! password: from a protocol-B host through the bridge's own station
//! ([`super::wire`]) and from the web page. One [`Editor`] per gateway,
//! over its [`PageStore`].
//!
//! - A host reads the page's first [`HOST_LEN`] bytes, stages a new page in
//!   windows written in order from offset 0 (the first erases the slot not
//!   in force), then applies it with the password and the CRC-32 of what it
//!   staged: the gateway checks that it staged exactly that, that every
//!   block present in it checks, copies the verifier block over from the
//!   page in force and commits. A web change writes its whole page at once.
//!   Either discards what a host had staged.
//! - A new password needs the current one, except on a fresh gateway (no
//!   verifier yet), where it is the only change taken.
//! - The web block and the password take effect at once (they are read
//!   from the page for every check); the other blocks at the next start
//!   ([`Editor::restart_pending`]). A restart goes [`RESTART_DELAY_MS`]
//!   after it was granted, so that its answer leaves first.

use super::access::{Check, Gate, PasswordError, Verifier, WebConfig, ACCESS_LEN, WEB_LEN};
use super::page::{ACCESS_AT, BRIDGE_AT, HOST_LEN, NET_AT, WEB_AT, WINDOW};
use super::settings::{copy_into, Block, SetError, Settings};
use super::store::{PageStore, StoreError};
use super::{Config, Crc32, MAGIC as BRIDGE_MAGIC};
use crate::net::config::{NetConfig, BLOCK_LEN as NET_LEN, MAGIC as NET_MAGIC};

/// How long after a granted restart the gateway restarts, ms.
pub const RESTART_DELAY_MS: u32 = 200;

/// Why a write or a restart was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// The password is wrong.
    WrongPassword,
    /// A wrong password came less than a second ago.
    Shut,
    /// No password is set yet: set one first.
    NoPassword,
    /// The staged page is incomplete, out of order, or not what the apply
    /// describes (or a web change discarded it).
    Staging,
    /// A block of the new page does not check (its name).
    Invalid(&'static str),
    /// A setting does not fit the others.
    Setting(SetError),
    /// The new password is not one ([`PasswordError`]).
    BadPassword(PasswordError),
    /// The store failed.
    Store(StoreError),
}

impl From<StoreError> for Refusal {
    fn from(e: StoreError) -> Self {
        Refusal::Store(e)
    }
}

/// A page written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Applied {
    /// Its sequence number.
    pub seq: u32,
    /// It changed what takes effect only at the next start.
    pub restart_needed: bool,
}

/// The writes of the configuration page (see the module docs).
pub struct Editor<'a> {
    store: &'a mut dyn PageStore,
    gate: Gate,
    /// Where a host's next staged bytes go, once it began.
    staged: Option<usize>,
    restart_pending: bool,
    restart_at: Option<u32>,
    restart: fn(),
    /// Restarts carried out (the board's `restart` may return in tests).
    pub restarts: u32,
    entropy: u32,
}

impl<'a> Editor<'a> {
    /// The editor of `store`; `restart` restarts the gateway (a board's
    /// reset); `entropy` differs at each boot (salts are made from it).
    pub fn new(store: &'a mut dyn PageStore, restart: fn(), entropy: u32) -> Self {
        Editor {
            store,
            gate: Gate::new(),
            staged: None,
            restart_pending: false,
            restart_at: None,
            restart,
            restarts: 0,
            entropy,
        }
    }

    /// The store.
    pub fn store(&mut self) -> &mut dyn PageStore {
        &mut *self.store
    }

    /// The sequence number of the page in force.
    pub fn sequence(&self) -> Option<u32> {
        self.store.current().map(|s| s.seq)
    }

    /// Changes were written that take effect at the next start.
    pub fn restart_pending(&self) -> bool {
        self.restart_pending
    }

    /// Wrong passwords so far.
    pub fn failures(&self) -> u32 {
        self.gate.failures
    }

    /// The password's verifier in force (`None`: no password yet).
    pub fn verifier(&mut self) -> Option<Verifier> {
        let mut block = [0u8; ACCESS_LEN];
        self.store.read(ACCESS_AT, &mut block).ok()?;
        Verifier::from_block(&block)
    }

    /// The web block in force.
    pub fn web(&mut self) -> WebConfig {
        let mut block = [0u8; WEB_LEN];
        match self.store.read(WEB_AT, &mut block) {
            Ok(()) => WebConfig::from_block(&block),
            Err(_) => WebConfig::DEFAULT,
        }
    }

    /// The settings in force.
    pub fn settings(&mut self) -> Settings {
        Settings::load(&mut *self.store).unwrap_or_default()
    }

    /// Checks `password` at `now` (a wrong one shuts the checks for a
    /// second).
    pub fn check(&mut self, password: &[u8], now: u32) -> Check {
        let v = self.verifier();
        self.gate.check(v.as_ref(), password, now)
    }

    /// Whether `password` may write. Not inlined, and called before the
    /// work of a write is set up: the password's check (SHA-256) is the
    /// deepest thing the bridge's loop calls, so no write's buffers are on
    /// the stack under it.
    #[inline(never)]
    fn grant(&mut self, password: &[u8], now: u32) -> Result<(), Refusal> {
        match self.check(password, now) {
            Check::Granted => Ok(()),
            Check::NoPassword => Err(Refusal::NoPassword),
            Check::Wrong => Err(Refusal::WrongPassword),
            Check::Shut => Err(Refusal::Shut),
        }
    }

    /// Reads the page in force at `at` (within its first [`HOST_LEN`]
    /// bytes; past them, [`StoreError::Range`]).
    pub fn read_host(&mut self, at: usize, buf: &mut [u8]) -> Result<(), Refusal> {
        if at.checked_add(buf.len()).is_none_or(|end| end > HOST_LEN) {
            return Err(Refusal::Store(StoreError::Range));
        }
        Ok(self.store.read(at, buf)?)
    }

    /// Reads the verifier block of the page in force, for a host that
    /// gives `password`.
    pub fn read_verifier(
        &mut self,
        password: &[u8],
        now: u32,
        buf: &mut [u8; ACCESS_LEN],
    ) -> Result<(), Refusal> {
        self.grant(password, now)?;
        self.store.read(ACCESS_AT, buf)?;
        Ok(())
    }

    /// Stages `bytes` of a host's new page at `at`: in order from 0 (which
    /// starts the page), within the first [`HOST_LEN`] bytes. Where the
    /// next bytes go.
    pub fn stage(&mut self, at: usize, bytes: &[u8]) -> Result<usize, Refusal> {
        let end = at
            .checked_add(bytes.len())
            .filter(|end| *end <= HOST_LEN)
            .ok_or(Refusal::Staging)?;
        if at == 0 {
            self.staged = None;
            self.store.begin()?;
            self.staged = Some(0);
        }
        if self.staged != Some(at) {
            return Err(Refusal::Staging);
        }
        if let Err(e) = self.store.write(at, bytes) {
            self.staged = None;
            return Err(e.into());
        }
        self.staged = Some(end);
        Ok(end)
    }

    /// Applies a host's staged page: `password` must be right and `crc` the
    /// CRC-32 of the [`HOST_LEN`] bytes staged.
    pub fn apply(&mut self, password: &[u8], crc: u32, now: u32) -> Result<Applied, Refusal> {
        self.grant(password, now)?;
        self.apply_granted(crc)
    }

    #[inline(never)]
    fn apply_granted(&mut self, crc: u32) -> Result<Applied, Refusal> {
        if self.staged != Some(HOST_LEN) {
            return Err(Refusal::Staging);
        }
        if self.staged_crc()? != crc {
            return Err(Refusal::Staging);
        }
        self.check_staged()?;
        let restart_needed = self.differs_outside_web()?;
        self.copy_verifier(None)?;
        self.staged = None;
        let seq = self.store.commit()?;
        self.restart_pending |= restart_needed;
        Ok(Applied {
            seq,
            restart_needed,
        })
    }

    /// Every block present in the staged page must check.
    fn check_staged(&mut self) -> Result<(), Refusal> {
        let mut bridge = [0u8; super::BLOCK_LEN];
        self.store.read_new(BRIDGE_AT, &mut bridge)?;
        if bridge.get(..4) == Some(&BRIDGE_MAGIC[..]) && Config::parse(&bridge).is_err() {
            return Err(Refusal::Invalid("bridge"));
        }
        let mut net = [0u8; NET_LEN];
        self.store.read_new(NET_AT, &mut net)?;
        if net.get(..4) == Some(&NET_MAGIC[..]) && NetConfig::parse(&net).is_err() {
            return Err(Refusal::Invalid("net"));
        }
        let mut web = [0u8; WEB_LEN];
        self.store.read_new(WEB_AT, &mut web)?;
        if web.get(..4) == Some(&super::access::WEB_MAGIC[..]) && WebConfig::parse(&web).is_err() {
            return Err(Refusal::Invalid("web"));
        }
        Ok(())
    }

    /// [`host_crc`] of the staged page.
    fn staged_crc(&mut self) -> Result<u32, Refusal> {
        let mut sum = Crc32::castagnoli();
        let mut window = [0u8; WINDOW];
        let mut at = 0;
        while at < HOST_LEN {
            let n = WINDOW.min(HOST_LEN - at);
            let w = window.get_mut(..n).ok_or(Refusal::Staging)?;
            self.store.read_new(at, w)?;
            sum = sum.update(w);
            at += n;
        }
        Ok(sum.finish())
    }

    /// Whether the staged page differs from the page in force outside the
    /// web block (what takes effect only at the next start).
    fn differs_outside_web(&mut self) -> Result<bool, Refusal> {
        let mut new = [0u8; WINDOW];
        let mut old = [0u8; WINDOW];
        let mut at = 0;
        while at < HOST_LEN {
            let n = WINDOW.min(HOST_LEN - at);
            let (Some(a), Some(b)) = (new.get_mut(..n), old.get_mut(..n)) else {
                return Err(Refusal::Staging);
            };
            self.store.read_new(at, a)?;
            self.store.read(at, b)?;
            copy_into(at, a, WEB_AT, &[0; WEB_LEN]);
            copy_into(at, b, WEB_AT, &[0; WEB_LEN]);
            if a != b {
                return Ok(true);
            }
            at += n;
        }
        Ok(false)
    }

    /// Writes the verifier block of the new page: `new`, or the one in
    /// force (nothing, if none: the slot is erased).
    fn copy_verifier(&mut self, new: Option<&Verifier>) -> Result<(), Refusal> {
        let mut block = [0xFFu8; ACCESS_LEN];
        match new {
            Some(v) => block = v.to_block(),
            None => self.store.read(ACCESS_AT, &mut block)?,
        }
        if block.iter().any(|&b| b != 0xFF) {
            self.store.write(ACCESS_AT, &block)?;
        }
        Ok(())
    }

    /// A verifier of `password` with a fresh salt. Not inlined, as
    /// [`Editor::grant`].
    #[inline(never)]
    fn new_verifier(&mut self, password: &[u8], now: u32) -> Result<Verifier, Refusal> {
        self.entropy = self.entropy.wrapping_mul(0x9E37_79B1).wrapping_add(now);
        let mut e = [0u8; 8];
        e[..4].copy_from_slice(&self.entropy.to_le_bytes());
        e[4..].copy_from_slice(&now.to_le_bytes());
        Verifier::new(password, Verifier::salt_from(&e)).map_err(Refusal::BadPassword)
    }

    /// Sets a new password: `current` must be right, unless none is set.
    pub fn set_password(
        &mut self,
        current: &[u8],
        new: &[u8],
        now: u32,
    ) -> Result<Applied, Refusal> {
        match self.grant(current, now) {
            Ok(()) | Err(Refusal::NoPassword) => {}
            Err(e) => return Err(e),
        }
        self.set_password_granted(new, now)
    }

    fn set_password_granted(&mut self, new: &[u8], now: u32) -> Result<Applied, Refusal> {
        let v = self.new_verifier(new, now)?;
        self.write_page(None, Some(&v))
    }

    /// Writes `settings`' changed blocks over the page in force (a web
    /// change): `password` must be right; on a fresh gateway (no password
    /// yet) `new_password` must be given, and then sets it. A new password
    /// given with the right one replaces it.
    pub fn commit_settings(
        &mut self,
        settings: &Settings,
        password: &[u8],
        new_password: Option<&[u8]>,
        now: u32,
    ) -> Result<Applied, Refusal> {
        match (self.grant(password, now), new_password) {
            (Ok(()), _) | (Err(Refusal::NoPassword), Some(_)) => {}
            (Err(e), _) => return Err(e),
        }
        self.commit_granted(settings, new_password, now)
    }

    fn commit_granted(
        &mut self,
        settings: &Settings,
        new_password: Option<&[u8]>,
        now: u32,
    ) -> Result<Applied, Refusal> {
        settings.check().map_err(Refusal::Setting)?;
        let v = match new_password {
            Some(p) => Some(self.new_verifier(p, now)?),
            None => None,
        };
        let applied = self.write_page(Some(settings), v.as_ref())?;
        let restart_needed = settings.changed(Block::Bridge) || settings.changed(Block::Net);
        self.restart_pending |= restart_needed;
        Ok(Applied {
            restart_needed,
            ..applied
        })
    }

    /// Writes a new page: the page in force, with `settings`' changed
    /// blocks over it and `verifier` (or the one in force).
    #[inline(never)]
    fn write_page(
        &mut self,
        settings: Option<&Settings>,
        verifier: Option<&Verifier>,
    ) -> Result<Applied, Refusal> {
        self.staged = None;
        self.store.begin()?;
        let mut window = [0u8; WINDOW];
        let mut at = 0;
        while at < HOST_LEN {
            let n = WINDOW.min(HOST_LEN - at);
            let w = window.get_mut(..n).ok_or(Refusal::Staging)?;
            self.store.read(at, w)?;
            if let Some(s) = settings {
                s.overlay(at, w);
            }
            // The slot is erased: erased bytes need no write.
            if w.iter().any(|&b| b != 0xFF) {
                self.store.write(at, w)?;
            }
            at += n;
        }
        self.copy_verifier(verifier)?;
        let seq = self.store.commit()?;
        Ok(Applied {
            seq,
            restart_needed: false,
        })
    }

    /// Grants a restart to `password`: the gateway restarts
    /// [`RESTART_DELAY_MS`] from `now` ([`Editor::poll`]).
    pub fn request_restart(&mut self, password: &[u8], now: u32) -> Result<(), Refusal> {
        self.grant(password, now)?;
        self.restart_at = Some(now.wrapping_add(RESTART_DELAY_MS));
        Ok(())
    }

    /// Whether a restart was granted and is yet to happen.
    pub fn restarting(&self) -> bool {
        self.restart_at.is_some()
    }

    /// Restarts the gateway if a granted restart is due at `now`.
    pub fn poll(&mut self, now: u32) {
        if let Some(at) = self.restart_at {
            if (now.wrapping_sub(at) as i32) >= 0 {
                self.restart_at = None;
                self.restarts = self.restarts.wrapping_add(1);
                self.restart_pending = false;
                (self.restart)();
            }
        }
    }
}

/// The CRC-32C of a page's host part ([`Crc32::castagnoli`]: a CRC-32
/// could not tell one valid block from another), as [`Editor::apply`]
/// expects it.
pub fn host_crc(page: &[u8]) -> u32 {
    Crc32::castagnoli()
        .update(page.get(..HOST_LEN).unwrap_or(page))
        .finish()
}

#[cfg(test)]
mod tests;
