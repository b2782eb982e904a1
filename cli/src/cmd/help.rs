//! The examples and notes shown after each command's `--help` (an
//! installed `iai` has no README beside it).

pub(crate) const IAI: &str = "\
Examples:
  iai simulate --tcp 127.0.0.1:5000 &            a controller to try things on
  iai send 212 query_axis_pattern=1 --tcp 127.0.0.1:5000
  iai table write table.csv --port /dev/ttyUSB0 --baud 38400
  iai inspect capture.log

Exit status: 0 done; 1 failed (the message says why); 2 bad arguments;
3 a resumed write left records unverified; 130 stopped by Ctrl-C.";

pub(crate) const INSPECT: &str = "\
Examples:
  iai inspect capture.bin                         raw bytes, or a text log (guessed)
  iai inspect --json capture.log | jq .fields
  iai encode 212 query_axis_pattern=1 | iai inspect -
  iai encode 212 query_axis_pattern=1 --raw | iai inspect --format raw -

Offsets are byte offsets in hex (0x0000001A). Beside the raw values: what
they mean where the manuals say (212H status bits as \"servo on, homed,
idle, positioning complete\", positions in mm, codes by name), and the
meaning of the bridge's and the simulator's error codes.";

pub(crate) const ENCODE: &str = "\
Examples:
  iai encode 232 axis_pattern=1 operation_type=on
  iai encode 234 speed=100 absolute_coordinate=100000,-25500     axis_pattern becomes 3
  iai encode 26D position_number=1,2 speed=100,200 position=-400000,1234/7
  iai encode 212 --fields
  iai encode error error_code=0x0E4
  iai inspect --json capture.log | head -1 | jq .fields > m.json && iai encode 26D --fields-file m.json

Values: decimal or 0x hex, one optional '-'; fields of a repeat group take
comma lists, '/' between the items of an outer group. Enumerated fields
also take their names (--fields lists them). A field may be left out only
where the manual gives 0 a meaning (acceleration, deceleration, speed: the
controller's parameter; --fields says which); an axis pattern before
per-axis values follows from their number.";

pub(crate) const MONITOR: &str = "\
Examples:
  iai monitor --port /dev/ttyUSB0 --baud 38400
  iai monitor --tcp 127.0.0.1:5000 --json --timestamps
  iai monitor --port COM3 --save capture.bin      then: iai inspect capture.bin";

pub(crate) const SEND: &str = "\
Examples:
  iai send 212 query_axis_pattern=1 --tcp 127.0.0.1:5000
  iai send 232 axis_pattern=1 operation_type=on --port /dev/ttyUSB0
  iai send 234 speed=100 absolute_coordinate=50000 --tcp 127.0.0.1:5000 --detail
  iai send 215 --tcp 127.0.0.1:5000 --json

With --json a failure is one JSON object too: {\"type\":\"failure\",
\"failure\":\"error_response\",\"code\":\"0E4\",...} (also \"timeout\",
\"outcome_unknown\", \"command\"), exit status 1.";

pub(crate) const TABLE_WRITE: &str = "\
Examples:
  iai table write table.csv --port /dev/ttyUSB0 --baud 38400
  iai table write table.csv --tcp 127.0.0.1:5000 --verify after-fault
  iai table write table.csv --tcp 127.0.0.1:5000 --resume      after an interruption
  iai table write table.csv --tcp 127.0.0.1:5000 --replace     the table becomes the file's
  iai table write table.csv --port /dev/ttyUSB0 --baud 115200 --bridge

The CSV format:
  number,acceleration,deceleration,speed,axis1,axis2,axis3
  1,0.30,0.30,100,100.000,-25.500,
  2,0.00,0.00,0,,,7.000

  number         position number, 0..=65535 (0..=4095 with --profile xsel2003)
  acceleration   G, at most 2 decimals, 0.00..=655.35 (0 = the controller's parameter)
  deceleration   the same
  speed          mm/s, integer, 0..=65535 (0 = parameter)
  axis1..axis8   mm with at most 3 decimals (degrees on a rotary axis),
                 -2147483.648..=2147483.647; an empty cell: the axis is not
                 in the record. Fewer than 8 axis columns are allowed.

The header is exactly the names above, ',' between cells, '.' as the
decimal point (a spreadsheet's ';' export is refused with a hint). Every
cell is checked before anything is sent. Positions not in the file keep
their values, unless --replace: it clears every position 246H reaches
(0..=8189) first and checks with 208H afterwards that the table holds the
file's records only. An interrupted write leaves FILE.csv.iai-state:
--resume continues it, --restart starts over.

--bridge: the bridge firmware must answer its status query (station BB,
--bridge-station); the whole table goes to it as one 26DH (up to 20,000
records; larger tables in several), XON/XOFF honoured. Its # with the count
means the controller holds every record of the message, each read back by
the bridge and compared, and the message's checksum was right. Its & says
only that it failed, not how far: any prefix of the records may be written
(after B01, B04 or B07 also records decoded from the corrupted bytes);
sending the table again puts every record right (position writes are
idempotent), which iai does for the bridge's transport codes up to
--retries times. No state file: there is nothing to resume.";

pub(crate) const TABLE_READ: &str = "\
Examples:
  iai table read --first 1 --count 100 --tcp 127.0.0.1:5000 > table.csv
  iai table read --all --port /dev/ttyUSB0 -o table.csv
  iai table read --all --port /dev/ttyUSB0 -o table.csv --resume     after an interruption

The output is the CSV form `table write` takes. --all asks 208H how many
positions are defined and stops once it has found them all. A read that
stops keeps what it read and says which positions that covers; into -o
FILE it leaves FILE.iai-read-state for --resume.";

pub(crate) const TABLE_CLEAR: &str = "\
Examples:
  iai table clear --first 10 --count 5 --tcp 127.0.0.1:5000
  iai table clear --all --port /dev/ttyUSB0

246H's fields are 3 hex digits: a clear starts at position 4095 at the
latest and spans at most 4095 positions, so it reaches 0..=8189. A range it
cannot clear without clearing others is refused before anything is sent;
--all exits 1 if 208H still counts positions afterwards (past 8189).";

pub(crate) const SIMULATE: &str = "\
Examples:
  iai simulate --tcp 127.0.0.1:0                  prints: listening tcp 127.0.0.1:PORT
  iai simulate --pty --quiet                      prints: listening pty /dev/pts/N
  iai simulate --tcp 127.0.0.1:5000 --faults drop=0.01,swap=0.05 --dump table.csv
  iai simulate --connect 127.0.0.1:5021           the bridge's controller side under QEMU

Its refusal codes (its own; the manuals publish none): 0E1 injected
(--faults error=P), 0E2 malformed or unknown message, 0E3 not modelled,
0E4 servo off, 0E5 not homed, 0E6 axis busy, 0E7 position not defined.";

pub(crate) const PORTS: &str = "\
Examples:
  iai ports
  iai ports --json

A pseudo-terminal (iai simulate --pty) is not listed: give it to --port.";

pub(crate) const PROBE: &str = "\
Examples:
  iai probe --port /dev/ttyUSB0                   every baud rate, the default stations
  iai probe --port COM3 --baud 38400,115200 --station 01,99
  iai probe --tcp 127.0.0.1:5000 --json

Each try tells what came back: the test call's text from that station (a
controller answers: use the --baud and --station it prints), an & reply,
our own frame (a loopback or an echoing converter), replies from another
station (tried next), or bytes that are not protocol B (a wrong baud rate
or framing). It stops at the first baud rate where a controller answers.";

pub(crate) const BRIDGE_STATUS: &str = "\
Examples:
  iai bridge status --tcp 127.0.0.1:PORT          the gateway (tools/gateway.sh)
  iai bridge status --port /dev/ttyUSB0 --baud 115200 --json
  iai bridge status --port COM3 --bridge-station B1

Shows the bridge's configuration (stations, baud rates, flow control,
policy), its counters (forwarded, relayed, 26DH ok/failed, records, chunks,
retries, overruns...) and its last own & code with what it means.";

pub(crate) const CONFIG_GET: &str = "\
Examples:
  iai bridge config get --tcp 127.0.0.1:PORT                 TOML: [modbus] unit = 1 ...
  iai bridge config get --port /dev/ttyUSB0 --baud 115200 --json
  iai bridge config get --tcp 127.0.0.1:PORT > gateway.toml  edit, then: iai bridge config apply gateway.toml
  iai bridge config get --tcp 127.0.0.1:PORT --image page.bin --password-file pw.txt

The page in force (B20H to the bridge's station, 64 bytes a message),
decoded with the firmware's own settings table. The password is never
shown (only whether one is set). --image writes the page as the board's
two slots, to load into a gateway with a programmer (with the password,
the image keeps it; without, the gateway that boots it asks for a new one).";

pub(crate) const CONFIG_SET: &str = "\
Examples:
  iai bridge config set access.password=NEW-PASSWORD --tcp 127.0.0.1:PORT      a fresh gateway: first of all
  iai bridge config set modbus.unit=5 modbus.baud=19200 --tcp 127.0.0.1:PORT --password-file pw.txt
  iai bridge config set bridge.policy=allow-list bridge.allow=212,215-217,26D --port COM3 --baud 115200
  IAI_BRIDGE_PASSWORD=... iai bridge config set web.reads=password --tcp 127.0.0.1:PORT
  then: iai bridge restart --tcp 127.0.0.1:PORT

Reads the page in force, changes the settings named (each checked against
the firmware's table: its range, its words), stages the whole page
(B21H) and applies it with the password (B22H); the gateway checks every
block again and writes the page to the slot not in force, so that a power
cut leaves the old page or the new one. Printed: the page's sequence
number and whether a restart is needed (all but web.* and the password
take effect at the next start). Refusals name the setting and why;
nothing is written then.";

pub(crate) const CONFIG_APPLY: &str = "\
Examples:
  iai bridge config get --tcp 127.0.0.1:PORT > gateway.toml
  iai bridge config apply gateway.toml --tcp 127.0.0.1:PORT --password-file pw.txt

gateway.toml:
  [modbus]
  unit = 5
  poll_ms = 50
  [net]
  addressing = \"static\"
  address = \"192.168.10.20/24\"

Every setting the file gives, as `config set` would; every error in the
file is listed before anything is sent. [access] password = \"...\" sets a
new password.";

pub(crate) const CONFIG_BLOCK: &str = "\
Examples:
  iai bridge config block gateway.toml -o config.bin                      for lm3s6965 (QEMU or an EK-LM3S6965)
  iai bridge config block gateway.toml -o config.bin --board stm32g070

The image holds both slots of the configuration page: the page in slot A
(sequence 1) and slot B erased, so that no older page there wins. Written
to the board's last two flash pages; the command to do it is printed on
stderr. A password in the file ([access] password) is stored as its
salted verifier.";

pub(crate) const BRIDGE_RESTART: &str = "\
Examples:
  iai bridge restart --tcp 127.0.0.1:PORT --password-file pw.txt
  IAI_BRIDGE_PASSWORD=... iai bridge restart --port /dev/ttyUSB0 --baud 115200

The gateway answers, then resets 200 ms later and reads its configuration
page again; this waits until its status query answers with a new uptime
(--wait 0: not at all).";
