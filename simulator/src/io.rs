//! The I/O model: output ports, global flags, global integer variables
//! and one idle program, for 20BH to 20EH, 24AH to 24CH and 213H.
//!
//! - Output ports and flags hold what 24AH and 24BH set (all off at
//!   start), and 20CH and 20DH report them.
//! - Input ports are wired to the output ports 300 above them: input port
//!   `n` reads what output port `n + 300` was set to (other inputs off).
//! - Integer variables hold what 24CH set (0 at start); 20EH reports them.
//!   Program numbers other than 0 (local variables) are kept apart.
//! - 213H reports every program as not running, step 0, no error.

use std::collections::{BTreeMap, BTreeSet};

use iai_protocol_b::message::{
    FlagQuery, FlagResponse, InputPortQuery, InputPortResponse, IntegerVariableQuery,
    IntegerVariableResponse, OutputPortQuery, OutputPortResponse, PortData, Repeated,
};

/// Ports, flags or variables one query may ask for at most here.
pub const MAX_QUERY: u16 = 1_024;

/// What the input ports are wired to: output port `n + 300` feeds input `n`.
pub const LOOPBACK_OFFSET: u16 = 300;

/// The controller's I/O and variables.
#[derive(Debug, Clone, Default)]
pub struct Io {
    /// Output ports that are on.
    pub outputs: BTreeSet<u16>,
    /// Flags that are on, by (program, flag).
    pub flags: BTreeSet<(u8, u16)>,
    /// Integer variables, by (program, variable).
    pub integers: BTreeMap<(u8, u16), i32>,
}

/// `count` states from `start`, 8 a byte, lowest first.
fn pack(count: u16, on: impl Fn(u16) -> bool, start: u16) -> Vec<u8> {
    let mut bytes = vec![0u8; usize::from(count).div_ceil(8)];
    for i in 0..count {
        if on(start.wrapping_add(i)) {
            if let Some(b) = bytes.get_mut(usize::from(i / 8)) {
                *b |= 1 << (i % 8);
            }
        }
    }
    bytes
}

impl Io {
    /// 20BH: the input ports (see the module docs); `None` if more than
    /// `MAX_QUERY` are asked.
    pub fn inputs(
        &self,
        q: &InputPortQuery,
        f: impl FnOnce(&InputPortResponse<'_>) -> Vec<u8>,
    ) -> Option<Vec<u8>> {
        let n = q.number_of_query_ports;
        (n <= MAX_QUERY).then(|| {
            let on = |p: u16| {
                p.checked_add(LOOPBACK_OFFSET)
                    .is_some_and(|o| self.outputs.contains(&o))
            };
            let bytes = pack(n, on, q.query_start_port_number);
            f(&InputPortResponse {
                response_start_port_number: q.query_start_port_number,
                input_port_data: PortData {
                    units: usize::from(n),
                    items: Repeated::from_slice(&bytes),
                },
            })
        })
    }

    /// 20CH: the output ports.
    pub fn outputs(
        &self,
        q: &OutputPortQuery,
        f: impl FnOnce(&OutputPortResponse<'_>) -> Vec<u8>,
    ) -> Option<Vec<u8>> {
        let n = q.number_of_query_ports;
        (n <= MAX_QUERY).then(|| {
            let bytes = pack(n, |p| self.outputs.contains(&p), q.query_start_port_number);
            f(&OutputPortResponse {
                response_start_port_number: q.query_start_port_number,
                output_port_data: PortData {
                    units: usize::from(n),
                    items: Repeated::from_slice(&bytes),
                },
            })
        })
    }

    /// 20DH: the flags of a program (0: global).
    pub fn flags(
        &self,
        q: &FlagQuery,
        f: impl FnOnce(&FlagResponse<'_>) -> Vec<u8>,
    ) -> Option<Vec<u8>> {
        let n = q.number_of_query_flags;
        (n <= MAX_QUERY).then(|| {
            let prog = q.program_number;
            let bytes = pack(
                n,
                |x| self.flags.contains(&(prog, x)),
                q.query_start_flag_number,
            );
            f(&FlagResponse {
                program_number: prog,
                response_start_flag_number: q.query_start_flag_number,
                flag_data: PortData {
                    units: usize::from(n),
                    items: Repeated::from_slice(&bytes),
                },
            })
        })
    }

    /// 20EH: integer variables of a program (0: global).
    pub fn integers(
        &self,
        q: &IntegerVariableQuery,
        f: impl FnOnce(&IntegerVariableResponse<'_>) -> Vec<u8>,
    ) -> Vec<u8> {
        let prog = q.program_number;
        let start = q.query_start_variable_number;
        let values: Vec<i32> = (0..u16::from(q.number_of_query_variables))
            .map(|i| {
                let v = start.wrapping_add(i);
                self.integers.get(&(prog, v)).copied().unwrap_or(0)
            })
            .collect();
        f(&IntegerVariableResponse {
            program_number: prog,
            response_start_variable_number: start,
            integer_variable_data: Repeated::from_slice(&values),
        })
    }

    /// 24AH.
    pub fn set_output(&mut self, port: u16, on: bool) {
        if on {
            self.outputs.insert(port);
        } else {
            self.outputs.remove(&port);
        }
    }

    /// 24BH.
    pub fn set_flag(&mut self, program: u8, flag: u16, on: bool) {
        if on {
            self.flags.insert((program, flag));
        } else {
            self.flags.remove(&(program, flag));
        }
    }

    /// 24CH: the variables written.
    pub fn set_integers(
        &mut self,
        program: u8,
        start: u16,
        values: impl Iterator<Item = i32>,
    ) -> u8 {
        let mut n = 0u8;
        for (i, v) in (0u16..).zip(values) {
            self.integers.insert((program, start.wrapping_add(i)), v);
            n = n.wrapping_add(1);
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ports_pack_lowest_first() {
        assert_eq!(pack(12, |p| p == 0 || p == 9, 0), vec![0x01, 0x02]);
    }
}
