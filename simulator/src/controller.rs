//! The controller's memory and its answers: [`Controller`] and
//! [`Controller::execute`], which parses each command once into the core's
//! typed [`Command`] and answers the messages below; every other one is
//! refused with [`NOT_MODELLED_CODE`].
//!
//! | message | answer |
//! |---|---|
//! | 200H Test Call | the 10 characters it was sent, exactly (2003 p. 15; the TTA page is not recovered, its layout is inferred identical) |
//! | 201H | the unit and device echoed, [`VERSION`]: the simulator's own codes, version and build date (no real controller's) |
//! | 208H | the number of records in the table (3 hex digits); more than FFFH records cannot be counted in that field and are refused with [`NOT_MODELLED_CODE`] rather than saturated |
//! | 209H, 21FH, 22DH | the defined records in the window asked for, as many as fit the transmit buffer |
//! | 244H, 245H, 26DH, 290H, 291H | the records stored, their count confirmed |
//! | 246H | `number_of_clear_positions` positions from `clear_start_position_number` (3-digit numbering) removed from the table, then acknowledged |
//! | 212H, 232H to 238H, 26BH | the axis model (`axis`) |
//! | 215H | AUTO mode, no system error, "operating in AUTO", "system ready" |
//! | 20BH, 20CH, 20DH, 20EH, 24AH, 24BH, 24CH, 213H | the I/O model (`io`): ports, flags, integer variables, an idle program |
//! | 252H | acknowledged (the simulator models no alarms) |
//! | 216H | illustrative details (error C74H, step 5, axis 2, point -3) |
//!
//! # Refusals
//! The manuals publish no code list (TTA p. 15, 2003 p. 13): these codes
//! are the simulator's own. `0E4` to `0E7` only with
//! [`Controller::refuse`] on (`iai simulate` turns it on, `--accept-all`
//! off).
//!
//! | code | refusal |
//! |---|---|
//! | [`INJECTED_ERROR_CODE`] `0E1` | fault injection (`error=P`) |
//! | [`UNSUPPORTED_ERROR_CODE`] `0E2` | body does not fit the layout, an ID outside the catalogue, an ID a 2003 X-SEL does not know (the TTA simulator knows every catalogue message), position number past FFFFH |
//! | [`NOT_MODELLED_CODE`] `0E3` | a catalogue message the simulator does not model; 208H with more than FFFH records |
//! | [`SERVO_OFF_CODE`] `0E4` | move, jog or home on an axis whose servo is off |
//! | [`NOT_HOMED_CODE`] `0E5` | 234H/235H/237H/26BH before the axis was homed (jog and inching are allowed) |
//! | [`AXIS_BUSY_CODE`] `0E6` | a new operation on an axis that is still moving or homing |
//! | [`NO_POSITION_CODE`] `0E7` | 237H/26BH to a position that is not defined or shares no axis with the pattern |

use std::collections::BTreeMap;

use iai_protocol_b::axis::{AxisPattern, PerAxis, MAX_AXES};
use iai_protocol_b::field::{FieldSpec, Writer};
use iai_protocol_b::frame::{emit_envelope, emit_trailer, Frame, Header, Station};
use iai_protocol_b::message::{
    AbsoluteMoveResponse, AlarmResetResponse, AxisStatus, AxisStatusResponse,
    ClearPositionDataResponse, Command, EffectivePositionCountResponse, ErrorDetailResponse,
    ErrorResponse, FlagChangeResponse, HomeReturnResponse, IntegerVariableChangeResponse,
    JogInchResponse, Message, OperationStopResponse, OutputPortChangeResponse,
    PositionNumberMove2Response, PositionNumberMoveResponse, PositionRecords,
    ProgramStatusResponse, RelativeMoveResponse, ServoOnOffResponse, SystemStatusResponse,
    TestCallResponse, VersionResponse,
};
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::profile::Profile;

use super::axis::{Axis, Home, Kind};
use super::io::Io;
use super::{
    Rng, AXIS_BUSY_CODE, DEFAULT_ACC, DEFAULT_SPEED, NOT_HOMED_CODE, NOT_MODELLED_CODE,
    NO_POSITION_CODE, REPLY_DELAY_MS, SERVO_OFF_CODE, SOFT_LIMIT, UNSUPPORTED_ERROR_CODE,
};

/// What the simulator answers 201H with (its own made-up codes: model 5AH,
/// unit 01H, version 0100H, built 2026-12-01 00:00:00).
pub const VERSION: VersionResponse = VersionResponse {
    unit_type: 0,
    device_number: 0,
    model_code: 0x5A,
    unit_code: 0x01,
    version_number: 0x0100,
    year: 2026,
    month: 12,
    day: 1,
    hour: 0,
    minute: 0,
    second: 0,
};

/// The controller's memory: position table, axes, limits.
#[derive(Debug, Clone)]
pub struct Controller {
    /// The kind of controller: which messages it knows.
    pub profile: Profile,
    /// Station code.
    pub station: Station,
    /// Largest command frame accepted (the constructors take the
    /// profile's [`Profile::max_command_frame`]).
    pub max_receive: usize,
    /// Largest response frame sent ([`Profile::max_response_frame`]).
    pub max_transmit: usize,
    /// Delay before replying (the controller's α), ms.
    pub response_delay_ms: u32,
    /// The position table.
    pub table: BTreeMap<u16, PositionRecord>,
    /// The eight axes.
    pub axes: [Axis; MAX_AXES],
    /// Position records written, over all connections.
    pub records_written: u64,
    /// Ports, flags and integer variables.
    pub io: Io,
    /// Refuse moves as described in the module docs (servo off, not
    /// homed, busy, undefined position). Off in the constructors, so that
    /// protocol tests get a normal response to every well-formed command
    /// the simulator models; `iai simulate` turns it on.
    pub refuse: bool,
}

/// A command's outcome: a reply frame, or nothing.
type Reply = Option<Vec<u8>>;

/// Acceleration, deceleration (0.01 G) and speed (mm/s) of a move.
type Profile3 = (u16, u16, u16);

impl Controller {
    /// A TTA at `station` ([`Profile::TTA`]'s buffers), α =
    /// [`REPLY_DELAY_MS`].
    pub fn tta(station: Station) -> Self {
        Controller {
            profile: Profile::TTA,
            station,
            max_receive: Profile::TTA.max_command_frame(),
            max_transmit: Profile::TTA.max_response_frame(),
            response_delay_ms: REPLY_DELAY_MS,
            table: BTreeMap::new(),
            axes: [Axis::default(); MAX_AXES],
            records_written: 0,
            io: Io::default(),
            refuse: false,
        }
    }

    /// A 2003-generation X-SEL ([`Profile::XSEL_2003`]'s buffers).
    pub fn xsel_2003(station: Station) -> Self {
        Controller {
            profile: Profile::XSEL_2003,
            max_receive: Profile::XSEL_2003.max_command_frame(),
            max_transmit: Profile::XSEL_2003.max_response_frame(),
            ..Self::tta(station)
        }
    }

    /// Brings every axis up to tick `now`.
    pub fn settle(&mut self, now: u32) {
        for a in self.axes.iter_mut() {
            a.settle(now);
        }
    }

    /// The `&` frame with `code` (3 hex digits).
    pub(super) fn error_frame(&self, code: u16) -> Vec<u8> {
        let mut buf = [0u8; 16];
        // 10 bytes always fit; every code used here has 3 digits.
        let n = ErrorResponse { code }
            .emit(self.station, &mut buf)
            .unwrap_or(0);
        buf.get(..n).unwrap_or_default().to_vec()
    }

    fn emit<'a, M: Message<'a>>(&self, msg: &M) -> Vec<u8> {
        let mut buf = vec![0u8; self.max_transmit];
        match msg.emit(self.station, &mut buf) {
            Ok(n) => {
                buf.truncate(n);
                buf
            }
            Err(_) => self.error_frame(UNSUPPORTED_ERROR_CODE),
        }
    }

    /// `msg` when the command was carried out, else the `&` frame of the
    /// refusal.
    fn answer<'a, M: Message<'a>>(&self, outcome: Result<(), u16>, msg: &M) -> Vec<u8> {
        match outcome {
            Ok(()) => self.emit(msg),
            Err(code) => self.error_frame(code),
        }
    }

    /// Executes one checked command at tick `now`; the reply frame, or
    /// `None` for no reply. `swap` alters one record of a position write.
    ///
    /// The frame is parsed once into its typed [`Command`]. A body that
    /// does not fit its layout, or an ID outside the catalogue (or one the
    /// profile does not know), is answered [`UNSUPPORTED_ERROR_CODE`]; a
    /// catalogue message the simulator does not model,
    /// [`NOT_MODELLED_CODE`].
    pub fn execute(&mut self, f: &Frame<'_>, now: u32, swap: Option<&mut Rng>) -> Reply {
        self.settle(now);
        if self.profile != Profile::TTA && !self.profile.supports(f.code()) {
            // A message this kind of controller does not know (the TTA
            // simulator knows every catalogue message, whatever family).
            return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
        }
        let Ok(cmd) = Command::parse(f) else {
            return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
        };
        let reply = match cmd {
            // 2003 p. 15: the same 10 characters back.
            Command::TestCall(c) => self.emit(&TestCallResponse {
                test_string: c.test_string,
            }),
            Command::VersionQuery(q) => self.emit(&VersionResponse {
                unit_type: q.unit_type,
                device_number: q.device_number,
                ..VERSION
            }),
            Command::EffectivePositionCountQuery(_) => self.count_positions(),
            Command::AxisStatusQuery(q) => self.axis_status(q.query_axis_pattern, now),
            // AUTO mode, no system error; byte 3: operating in AUTO, system
            // ready. 215H has no motion field: moves show in 212H only.
            Command::SystemStatusQuery(_) => self.emit(&SystemStatusResponse {
                system_mode: 1,
                status_byte_3: 0b110,
                ..SystemStatusResponse::default()
            }),
            // Illustrative details (error C74H, program 1, step 5, axis 2,
            // point -3).
            Command::ErrorDetailQuery(q) => self.emit(&ErrorDetailResponse {
                error_number: 0xC74,
                detail_1: u32::from(q.type_2),
                detail_2: 5,
                detail_3: 2,
                detail_4: -3,
                ..ErrorDetailResponse::default()
            }),
            Command::ServoOnOff(c) => {
                let on = c.operation_type & 1 == 1;
                for n in c.axis_pattern.iter() {
                    if let Some(a) = self.axes.get_mut(usize::from(n) - 1) {
                        if !on {
                            a.stop(now);
                        }
                        a.servo = on;
                    }
                }
                self.emit(&ServoOnOffResponse {})
            }
            Command::HomeReturn(c) => {
                let speed = if c.end_search_speed == 0 {
                    DEFAULT_SPEED
                } else {
                    c.end_search_speed
                };
                let targets: Vec<(u8, i32)> = c.axis_pattern.iter().map(|n| (n, 0)).collect();
                let done = self.start(&targets, Kind::Home, now, (0, 0, speed), false);
                self.answer(done, &HomeReturnResponse {})
            }
            Command::AbsoluteMove(c) => {
                let targets: Vec<(u8, i32)> = c
                    .axis_pattern
                    .iter()
                    .zip(c.absolute_coordinate.iter().copied())
                    .collect();
                let p = (c.acceleration, c.deceleration, c.speed);
                let done = self.start(&targets, Kind::Move, now, p, true);
                self.answer(done, &AbsoluteMoveResponse {})
            }
            Command::RelativeMove(c) => {
                let targets: Vec<(u8, i32)> = c
                    .axis_pattern
                    .iter()
                    .zip(c.relative_distance.iter().copied())
                    .map(|(n, d)| (n, self.axis_pos(n, now).saturating_add(d)))
                    .collect();
                let p = (c.acceleration, c.deceleration, c.speed);
                let done = self.start(&targets, Kind::Move, now, p, true);
                self.answer(done, &RelativeMoveResponse {})
            }
            Command::JogInch(c) => {
                let positive = c.operation_type & 1 == 1;
                let targets: Vec<(u8, i32)> = c
                    .axis_pattern
                    .iter()
                    .map(|n| {
                        let here = self.axis_pos(n, now);
                        let to = match (c.inching_distance, positive) {
                            (0, true) => SOFT_LIMIT,
                            (0, false) => -SOFT_LIMIT,
                            (d, true) => here.saturating_add_unsigned(d),
                            (d, false) => here.saturating_sub_unsigned(d),
                        };
                        (n, to.clamp(-SOFT_LIMIT, SOFT_LIMIT))
                    })
                    .collect();
                let p = (c.acceleration, c.deceleration, c.speed);
                let done = self.start(&targets, Kind::Move, now, p, false);
                self.answer(done, &JogInchResponse {})
            }
            Command::PositionNumberMove(c) => {
                let p = (c.acceleration, c.deceleration, c.speed);
                let done = self.move_to_position(c.axis_pattern, c.position_number, p, now);
                self.answer(done, &PositionNumberMoveResponse {})
            }
            Command::PositionNumberMove2(c) => {
                let p = (c.acceleration, c.deceleration, c.speed);
                let done = self.move_to_position(c.axis_pattern, c.position_number, p, now);
                self.answer(done, &PositionNumberMove2Response {})
            }
            Command::OperationStop(c) => {
                for n in c.stop_axis_pattern.iter() {
                    if let Some(a) = self.axes.get_mut(usize::from(n) - 1) {
                        a.stop(now);
                    }
                }
                self.emit(&OperationStopResponse {})
            }
            Command::ChangePositionData2(c) => {
                self.write_positions(PositionStream::CHANGE_2, 0, &c.records, swap)
            }
            Command::ChangePositionData(c) => {
                self.write_positions(PositionStream::CHANGE, 0, &c.records, swap)
            }
            Command::RangeWritePositionData(c) => self.write_positions(
                PositionStream::RANGE,
                c.change_start_position_number,
                &c.records,
                swap,
            ),
            Command::RangeWritePositionData2(c) => self.write_positions(
                PositionStream::RANGE_3,
                c.change_start_position_number,
                &c.records,
                swap,
            ),
            Command::ChangePositionData3(c) => {
                self.write_positions(PositionStream::CHANGE_3, 0, &c.records, swap)
            }
            Command::ClearPositionData(c) => {
                self.clear_positions(c.clear_start_position_number, c.number_of_clear_positions);
                self.emit(&ClearPositionDataResponse {})
            }
            Command::EffectivePositionQuery(q) => self.query_positions(
                PositionStream::QUERY_RESPONSE,
                q.query_head_position_number,
                q.number_of_query_records,
            ),
            Command::EffectivePositionQuery2(q) => self.query_positions(
                PositionStream::QUERY_2_RESPONSE,
                q.query_head_position_number,
                q.number_of_query_records,
            ),
            Command::EffectivePositionQuery3(q) => self.query_positions(
                PositionStream::QUERY_3_RESPONSE,
                q.query_head_position_number,
                q.number_of_query_records,
            ),
            Command::InputPortQuery(q) => self.or_refused(self.io.inputs(&q, |r| self.emit(r))),
            Command::OutputPortQuery(q) => self.or_refused(self.io.outputs(&q, |r| self.emit(r))),
            Command::FlagQuery(q) => self.or_refused(self.io.flags(&q, |r| self.emit(r))),
            Command::IntegerVariableQuery(q) => self.io.integers(&q, |r| self.emit(r)),
            Command::OutputPortChange(c) => {
                self.io
                    .set_output(c.output_port_number, c.change_type & 1 == 1);
                self.emit(&OutputPortChangeResponse {})
            }
            Command::FlagChange(c) => {
                self.io
                    .set_flag(c.program_number, c.flag_number, c.change_type & 1 == 1);
                self.emit(&FlagChangeResponse {})
            }
            Command::IntegerVariableChange(c) => {
                let n = self.io.set_integers(
                    c.program_number,
                    c.change_start_variable_number,
                    c.integer_variable_data.iter(),
                );
                self.emit(&IntegerVariableChangeResponse {
                    program_number: c.program_number,
                    change_start_variable_number: c.change_start_variable_number,
                    number_of_changed_variables: n,
                })
            }
            // Not running, step 0, no error.
            Command::ProgramStatusQuery(q) => self.emit(&ProgramStatusResponse {
                program_number: q.program_number,
                ..ProgramStatusResponse::default()
            }),
            Command::AlarmReset(_) => self.emit(&AlarmResetResponse {}),
            // Every other message: refused rather than answered with made-up
            // fields (see "Refusals" in the module docs).
            _ => self.error_frame(NOT_MODELLED_CODE),
        };
        Some(reply)
    }

    /// A modelled reply, or the refusal of a query larger than the model
    /// answers ([`NOT_MODELLED_CODE`]).
    fn or_refused(&self, reply: Option<Vec<u8>>) -> Vec<u8> {
        reply.unwrap_or_else(|| self.error_frame(NOT_MODELLED_CODE))
    }

    fn axis_pos(&self, n: u8, now: u32) -> i32 {
        self.axes
            .get(usize::from(n) - 1)
            .map_or(0, |a| a.position(now))
    }

    /// 212H: status byte and position at `now` of each axis asked for.
    fn axis_status(&self, pattern: AxisPattern, now: u32) -> Vec<u8> {
        let mut axes = PerAxis::new();
        for n in pattern.iter() {
            let a = self
                .axes
                .get(usize::from(n) - 1)
                .copied()
                .unwrap_or_default();
            let _ = axes.push(AxisStatus {
                axis_status: a.status_byte(),
                sensor_input_status: 0,
                error_code: 0,
                encoder_status: 0,
                current_position: a.position(now),
            });
        }
        self.emit(&AxisStatusResponse {
            axis_pattern: pattern,
            axes,
        })
    }

    /// 237H / 26BH: to the coordinates of position `number` on the axes of
    /// `pattern` that the record has. Zero profile values take the
    /// record's, then the defaults.
    fn move_to_position(
        &mut self,
        pattern: AxisPattern,
        number: u16,
        (acc, dec, speed): Profile3,
        now: u32,
    ) -> Result<(), u16> {
        if pattern.is_empty() {
            // No axis concerned: nothing to move, nothing to refuse.
            return Ok(());
        }
        let undefined = if self.refuse {
            Err(NO_POSITION_CODE)
        } else {
            Ok(())
        };
        let Some(rec) = self.table.get(&number).cloned() else {
            return undefined;
        };
        let targets: Vec<(u8, i32)> = pattern
            .iter()
            .filter_map(|n| rec.position(n).map(|p| (n, p)))
            .collect();
        if targets.is_empty() {
            return undefined;
        }
        let pick = |given: u16, stored: u16, default: u16| {
            [given, stored]
                .into_iter()
                .find(|v| *v != 0)
                .unwrap_or(default)
        };
        let p = (
            pick(acc, rec.acceleration, DEFAULT_ACC),
            pick(dec, rec.deceleration, DEFAULT_ACC),
            pick(speed, rec.speed, DEFAULT_SPEED),
        );
        self.start(&targets, Kind::Move, now, p, true)
    }

    /// Starts a move (or homing) of each `(axis, target)`: all or none.
    fn start(
        &mut self,
        targets: &[(u8, i32)],
        kind: Kind,
        now: u32,
        (acc, dec, speed): Profile3,
        needs_home: bool,
    ) -> Result<(), u16> {
        let or = |v: u16, d: u16| if v == 0 { d } else { v };
        let p = (
            or(acc, DEFAULT_ACC),
            or(dec, DEFAULT_ACC),
            or(speed, DEFAULT_SPEED),
        );
        for &(n, _) in targets {
            let a = self
                .axes
                .get(usize::from(n) - 1)
                .ok_or(UNSUPPORTED_ERROR_CODE)?;
            if !self.refuse {
                continue;
            }
            if !a.servo {
                return Err(SERVO_OFF_CODE);
            }
            if a.in_use() {
                return Err(AXIS_BUSY_CODE);
            }
            if needs_home && a.home != Home::Done {
                return Err(NOT_HOMED_CODE);
            }
        }
        for &(n, to) in targets {
            if let Some(a) = self.axes.get_mut(usize::from(n) - 1) {
                a.begin(kind, to, now, p);
            }
        }
        Ok(())
    }

    /// 208H: how many records the table holds. A count its field cannot
    /// carry (3 hex digits: more than FFFH) is refused with
    /// [`NOT_MODELLED_CODE`] (what a TTA answers then is not known).
    fn count_positions(&self) -> Vec<u8> {
        let count = u16::try_from(self.table.len()).map(|n| EffectivePositionCountResponse {
            number_of_effective_positions: n,
        });
        let mut buf = vec![0u8; self.max_transmit];
        match count.map(|msg| msg.emit(self.station, &mut buf)) {
            Ok(Ok(n)) => {
                buf.truncate(n);
                buf
            }
            _ => self.error_frame(NOT_MODELLED_CODE),
        }
    }

    /// 246H: clears positions `start..start + count`.
    fn clear_positions(&mut self, start: u16, count: u16) {
        let end = start.saturating_add(count);
        let gone: Vec<u16> = self.table.range(start..end).map(|(k, _)| *k).collect();
        for k in gone {
            self.table.remove(&k);
        }
    }

    /// 244H / 245H / 26DH / 290H / 291H: stores the records (numbered from
    /// `start` for the range writes, whose records carry no number) and
    /// confirms how many.
    fn write_positions(
        &mut self,
        kind: PositionStream,
        start: u16,
        records: &PositionRecords<'_>,
        swap: Option<&mut Rng>,
    ) -> Vec<u8> {
        let numbered = kind.layout.number_width > 0;
        let recs: Option<Vec<PositionRecord>> = records
            .iter()
            .zip(0u16..)
            .map(|(mut rec, i)| {
                if !numbered {
                    // A range write past position FFFFH has nowhere to go.
                    rec.number = start.checked_add(i)?;
                }
                Some(rec)
            })
            .collect();
        let Some(mut recs) = recs.filter(|r| r.len() == records.len()) else {
            return self.error_frame(UNSUPPORTED_ERROR_CODE);
        };
        if let Some(rng) = swap {
            swap_digits(&mut recs, rng);
        }
        let n = recs.len() as u16;
        for rec in recs {
            self.table.insert(rec.number, rec);
        }
        self.records_written += u64::from(n);
        let mut buf = [0u8; 32];
        let mut w = Writer::new(&mut buf);
        let ok = emit_envelope(&mut w, Header::Response, self.station, kind.id)
            .and_then(|_| kind.write_prefix(&mut w, start, n))
            .and_then(|_| emit_trailer(&mut w, Default::default()));
        match ok {
            Ok(()) => w.written().to_vec(),
            Err(_) => self.error_frame(UNSUPPORTED_ERROR_CODE),
        }
    }

    /// 209H / 21FH / 22DH: the defined records in the window of position
    /// numbers `head..head + asked`, as many as fit the transmit buffer.
    fn query_positions(&self, kind: PositionStream, head: u16, asked: u16) -> Vec<u8> {
        let mut buf = vec![0u8; self.max_transmit];
        let mut w = Writer::new(&mut buf);
        let written = (|| {
            emit_envelope(&mut w, Header::Response, self.station, kind.id)?;
            kind.write_prefix(&mut w, 0, 0)?;
            let count_at = w.len() - usize::from(kind.count_width);
            let mut n = 0u16;
            // The window head..head+asked; only defined records are returned.
            let end = u32::from(head) + u32::from(asked);
            for rec in self
                .table
                .range(head..)
                .map(|(_, r)| r)
                .take_while(|r| u32::from(r.number) < end)
            {
                if w.len() + kind.layout.record_len(rec.axes.count()) + 4 > self.max_transmit {
                    break;
                }
                kind.layout.write_record(rec, &mut w)?;
                n += 1;
            }
            w.patch_unsigned(count_at, FieldSpec::hex(kind.count_width), u64::from(n))?;
            emit_trailer(&mut w, Default::default())
        })();
        match written {
            Ok(()) => w.written().to_vec(),
            Err(_) => self.error_frame(UNSUPPORTED_ERROR_CODE),
        }
    }
}

/// Swaps two adjacent, different hex digits of one coordinate of one
/// record: the sum of the frame's characters, hence its SC, is unchanged.
fn swap_digits(recs: &mut [PositionRecord], rng: &mut Rng) {
    let with_coords: Vec<usize> = (0..recs.len())
        .filter(|&i| recs.get(i).is_some_and(|r| !r.positions.is_empty()))
        .collect();
    let Some(&i) = with_coords.get(rng.below(with_coords.len() as u64) as usize) else {
        return;
    };
    let Some(rec) = recs.get_mut(i) else { return };
    let k = rng.below(rec.positions.len() as u64) as usize;
    let Some(p) = rec.positions.get_mut(k) else {
        return;
    };
    let digits = format!("{:08X}", *p as u32).into_bytes();
    let pairs: Vec<usize> = (0..7)
        .filter(|&j| digits.get(j) != digits.get(j + 1))
        .collect();
    let Some(&j) = pairs.get(rng.below(pairs.len() as u64) as usize) else {
        // All eight digits equal (0, -1): change the speed's digits instead.
        rec.speed = rec.speed.rotate_left(4);
        return;
    };
    let mut d = digits;
    d.swap(j, j + 1);
    let text = String::from_utf8_lossy(&d).into_owned();
    if let Ok(v) = u32::from_str_radix(&text, 16) {
        *p = v as i32;
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use iai_protocol_b::catalogue;
    use iai_protocol_b::checksum::BypassPolicy;

    const ST: Station = Station(0x99);

    /// The reply of `ctl` to the frame `cmd` at tick `now`, as text.
    fn exec(ctl: &mut Controller, cmd: &str, now: u32) -> String {
        let f = Frame::new_checked(cmd.as_bytes(), BypassPolicy::Reject).unwrap();
        let reply = ctl.execute(&f, now, None).unwrap();
        String::from_utf8(reply).unwrap()
    }

    /// Four one-axis records, positions 1, 2, 3 and 5 (26DH, 4-digit numbers).
    const WRITE_1_2_3_5: &str = "!9926D0004\
        000101001E001E0064000003E8\
        000201001E001E0064000007D0\
        000301001E001E006400000BB8\
        000501001E001E006400001388E5\r\n";

    #[test]
    fn a_test_call_comes_back_with_the_same_ten_characters() {
        let mut ctl = Controller::tta(ST);
        assert_eq!(
            exec(&mut ctl, "!99200ABCDEFGHIJDC\r\n", 0),
            "#99200ABCDEFGHIJDE\r\n"
        );
        // Any text, as a host's ordering fence would carry it.
        assert_eq!(
            exec(&mut ctl, "!99200fence-004219\r\n", 0),
            "#99200fence-00421B\r\n"
        );
    }

    #[test]
    fn the_count_of_positions_follows_the_table() {
        let mut ctl = Controller::tta(ST);
        assert_eq!(exec(&mut ctl, "!992082D\r\n", 0), "#99208000BF\r\n");
        assert_eq!(exec(&mut ctl, WRITE_1_2_3_5, 0), "#9926D000405\r\n");
        assert_eq!(exec(&mut ctl, "!992082D\r\n", 0), "#99208004C3\r\n");
        // FFFH records still fit the 3-digit count; one more does not and
        // is refused rather than saturated.
        let rec = PositionRecord::new(0, 1, 1, 1, &[(1, 5)]).unwrap();
        ctl.table = (0..0xFFF)
            .map(|n| {
                (
                    n,
                    PositionRecord {
                        number: n,
                        ..rec.clone()
                    },
                )
            })
            .collect();
        assert_eq!(exec(&mut ctl, "!992082D\r\n", 0), "#99208FFF01\r\n");
        ctl.table.insert(0xFFF, rec);
        assert_eq!(exec(&mut ctl, "!992082D\r\n", 0), "&990E340\r\n");
    }

    #[test]
    fn a_clear_removes_its_positions_and_the_query_no_longer_shows_them() {
        let mut ctl = Controller::tta(ST);
        exec(&mut ctl, WRITE_1_2_3_5, 0);
        assert_eq!(
            exec(&mut ctl, "!9921F00000010BD\r\n", 0),
            "#9921F0004\
             000101001E001E0064000003E8\
             000201001E001E0064000007D0\
             000301001E001E006400000BB8\
             000501001E001E006400001388E4\r\n"
        );
        // Clear 2 positions from 002: 2 and 3 go, 1 and 5 stay.
        assert_eq!(exec(&mut ctl, "!9924600200253\r\n", 0), "#9924631\r\n");
        assert_eq!(
            exec(&mut ctl, "!9921F00000010BD\r\n", 0),
            "#9921F0002\
             000101001E001E0064000003E8\
             000501001E001E00640000138868\r\n"
        );
        assert_eq!(exec(&mut ctl, "!992082D\r\n", 0), "#99208002C1\r\n");
        // Clearing nothing, or positions that are not defined, is no error.
        let f = |s: &str| {
            let sc = s.bytes().map(u32::from).sum::<u32>() & 0xFF;
            format!("{s}{sc:02X}\r\n")
        };
        assert_eq!(exec(&mut ctl, &f("!99246FFF000"), 0), "#9924631\r\n");
        assert_eq!(exec(&mut ctl, &f("!99246FFFFFF"), 0), "#9924631\r\n");
        assert_eq!(ctl.table.len(), 2);
    }

    #[test]
    fn output_300_drives_input_0_and_variables_keep_what_is_written() {
        let mut ctl = Controller::tta(ST);
        // 24AH: output port 300 (012CH) on.
        assert_eq!(exec(&mut ctl, "!9924A012C141\r\n", 0), "#9924A3C\r\n");
        // 20BH, 16 ports from 0: input 0 reads output 300.
        assert_eq!(
            exec(&mut ctl, "!9920B00000010B8\r\n", 0),
            "#9920B0000001001007B\r\n"
        );
        // 24CH: global variables 200 (0C8H) and 201 := 100 and -1.
        assert_eq!(
            exec(&mut ctl, "!9924C000C80200000064FFFFFFFF63\r\n", 0),
            "#9924C000C802AB\r\n"
        );
        assert_eq!(
            exec(&mut ctl, "!9920E000C802A7\r\n", 0),
            "#9920E000C80200000064FFFFFFFF63\r\n"
        );
    }

    #[test]
    fn version_201h_answers_the_simulators_own_codes() {
        let mut ctl = Controller::tta(ST);
        // Main CPU application, device 0: model 5A, unit 01, version 0100,
        // built 2026 (07EA) December 1, 00:00:00.
        assert_eq!(
            exec(&mut ctl, "!99201000B6\r\n", 0),
            "#992010005A01010007EA0C0100000031\r\n"
        );
    }

    #[test]
    fn a_message_the_simulator_does_not_model_is_refused() {
        let mut ctl = Controller::tta(ST);
        ctl.table
            .insert(1, PositionRecord::new(1, 1, 1, 1, &[(1, 5)]).unwrap());
        // 25BH software reset.
        assert_eq!(exec(&mut ctl, "!9925B3C\r\n", 0), "&990E340\r\n");
        // An ID outside the catalogue, a body that does not fit (212H without
        // its axis pattern): 0E2.
        assert_eq!(exec(&mut ctl, "!992FF51\r\n", 0), "&990E23F\r\n");
        assert_eq!(exec(&mut ctl, "!9921228\r\n", 0), "&990E23F\r\n");
        assert_eq!(ctl.table.len(), 1, "nothing executed");
    }

    #[test]
    fn every_catalogue_command_is_answered_or_refused_as_documented() {
        // The messages the module docs list as modelled.
        let modelled = [
            &catalogue::TEST_CALL,
            &catalogue::VERSION_QUERY,
            &catalogue::EFFECTIVE_POSITION_COUNT_QUERY,
            &catalogue::EFFECTIVE_POSITION_QUERY,
            &catalogue::EFFECTIVE_POSITION_QUERY_2,
            &catalogue::EFFECTIVE_POSITION_QUERY_3,
            &catalogue::RANGE_WRITE_POSITION_DATA,
            &catalogue::CHANGE_POSITION_DATA,
            &catalogue::CHANGE_POSITION_DATA_2,
            &catalogue::RANGE_WRITE_POSITION_DATA_3,
            &catalogue::CHANGE_POSITION_DATA_3,
            &catalogue::CLEAR_POSITION_DATA,
            &catalogue::AXIS_STATUS_QUERY,
            &catalogue::SERVO_ON_OFF,
            &catalogue::HOME_RETURN,
            &catalogue::ABSOLUTE_MOVE,
            &catalogue::RELATIVE_MOVE,
            &catalogue::JOG_INCH,
            &catalogue::POSITION_NUMBER_MOVE,
            &catalogue::OPERATION_STOP,
            &catalogue::POSITION_NUMBER_MOVE_2,
            &catalogue::SYSTEM_STATUS_QUERY,
            &catalogue::ERROR_DETAIL_QUERY,
            &catalogue::INPUT_PORT_QUERY,
            &catalogue::OUTPUT_PORT_QUERY,
            &catalogue::FLAG_QUERY,
            &catalogue::INTEGER_VARIABLE_QUERY,
            &catalogue::OUTPUT_PORT_CHANGE,
            &catalogue::FLAG_CHANGE,
            &catalogue::INTEGER_VARIABLE_CHANGE,
            &catalogue::PROGRAM_STATUS_QUERY,
            &catalogue::ALARM_RESET,
        ]
        .map(|m| m.id);
        let mut ctl = Controller::tta(ST);
        for id in catalogue::ALL.iter().map(|m| m.id) {
            let mut buf = [0u8; 64];
            let n = Command::default_for(id)
                .unwrap()
                .emit(ST, &mut buf)
                .unwrap();
            let f = Frame::new_checked(&buf[..n], BypassPolicy::Reject).unwrap();
            let reply = ctl.execute(&f, 0, None).unwrap();
            let r = Frame::new_checked(&reply, BypassPolicy::Reject).unwrap();
            if modelled.contains(&id) {
                assert_eq!((r.header(), r.code()), (Header::Response, id), "{id:03X}H");
            } else {
                assert_eq!(
                    (r.header(), r.code()),
                    (Header::Error, NOT_MODELLED_CODE),
                    "{id:03X}H"
                );
            }
        }
    }

    #[test]
    fn a_2003_x_sel_does_not_know_the_tta_messages() {
        let mut ctl = Controller::xsel_2003(ST);
        assert_eq!(exec(&mut ctl, WRITE_1_2_3_5, 0), "&990E23F\r\n");
        assert_eq!(exec(&mut ctl, "!992082D\r\n", 0), "#99208000BF\r\n");
    }

    #[test]
    fn a_swapped_record_keeps_the_checksum() {
        let mut rng = Rng::new(3);
        let orig = PositionRecord::new(1, 1, 1, 1, &[(1, 0x1234_5678)]).unwrap();
        let mut recs = vec![orig.clone()];
        swap_digits(&mut recs, &mut rng);
        let changed = recs.first().unwrap();
        assert_ne!(changed, &orig);
        let digit_sum = |r: &PositionRecord| -> u32 {
            format!("{:08X}", *r.positions.first().unwrap() as u32)
                .bytes()
                .map(u32::from)
                .sum()
        };
        assert_eq!(digit_sum(changed), digit_sum(&orig));
    }
}
