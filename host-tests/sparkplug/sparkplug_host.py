#!/usr/bin/env python3
"""A Sparkplug B 3.0 host for the end-to-end test (host-tests/tests/qemu_sparkplug.rs).

Subscribes to spBv1.0/# on an MQTT broker (paho-mqtt), decodes every payload
with sparkplug_b.proto (compiled at start with protoc, package `protobuf`),
checks what a host can check on its own and prints each message as one JSON
line on stdout:

  {"topic": T, "kind": "NBIRTH", "seq": S, "bytes": payload length,
   "metrics": [{"name", "alias", "datatype", "value"}...], "errors": [...]}

Checks, reported in "errors" (an empty list: none):
- BIRTH metrics carry a name, an alias and a data type, and the value field
  the data type asks for (Sparkplug 3.0, 6.4.16);
- DATA metrics name a known alias (from the last BIRTH) and carry the value
  field of its data type, and only values that changed (by exception);
- seq: NBIRTH 0, then one more per message of the node (DEATH excepted),
  wrapping at 256;
- NDEATH carries bdSeq (Int64).
A node whose NBIRTH the host has not seen since it connected (to the broker,
or again after the broker restarted) is asked for a rebirth (NCMD), as a
Sparkplug host does, and its messages are not judged until its NBIRTH.

Commands, one JSON object per line on stdin:
  {"state": true|false}          publish spBv1.0/STATE/HOST (retained, QoS 1)
  {"rebirth": NODE}              NCMD Node Control/Rebirth = true
  {"dcmd": NODE, "metrics": [{"name": N, "type": "Boolean"|"Int32"|"UInt16"|"Bytes", "value": V}]}
Prints {"ready": true} once subscribed. Ends when stdin closes.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

import paho.mqtt.client as mqtt

HERE = os.path.dirname(os.path.abspath(__file__))
TYPES = {"Int8": 1, "Int16": 2, "Int32": 3, "Int64": 4, "UInt8": 5, "UInt16": 6,
         "UInt32": 7, "UInt64": 8, "Boolean": 11, "String": 12, "Bytes": 17}
INT_TYPES = {1, 2, 3, 5, 6, 7}
LONG_TYPES = {4, 8, 13}
FIELD_OF = {**{t: "int_value" for t in INT_TYPES}, **{t: "long_value" for t in LONG_TYPES},
            9: "float_value", 10: "double_value", 11: "boolean_value", 12: "string_value",
            14: "string_value", 17: "bytes_value"}
SIGNED_BITS = {1: 8, 2: 16, 3: 32, 4: 64}


def compile_proto():
    out = tempfile.mkdtemp(prefix="spb-")
    subprocess.run(["protoc", f"--proto_path={HERE}", f"--python_out={out}",
                    os.path.join(HERE, "sparkplug_b.proto")], check=True)
    sys.path.insert(0, out)
    import sparkplug_b_pb2  # noqa: E402
    return sparkplug_b_pb2


def value_of(m, datatype):
    field = m.WhichOneof("value")
    if field is None:
        return None
    v = getattr(m, field)
    if datatype in SIGNED_BITS:
        bits = SIGNED_BITS[datatype]
        width = 32 if field == "int_value" else 64
        v &= (1 << width) - 1
        v &= (1 << bits) - 1
        if v >= 1 << (bits - 1):
            v -= 1 << bits
    if isinstance(v, bytes):
        v = v.hex()
    return v


class Host:
    def __init__(self, args, pb):
        self.args, self.pb = args, pb
        self.lock = threading.Lock()
        self.types = {}  # (node, device) -> {alias: (name, datatype)}
        self.values = {}  # (node, device) -> {alias: value}
        self.seq = {}  # node -> last seq
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=args.host_id or "spb-test-host",
                                  protocol=mqtt.MQTTv311)
        if args.username:
            self.client.username_pw_set(args.username, args.password)
        self.client.on_connect = self.on_connect
        self.client.on_message = self.on_message
        self.rebirth_asked = set()
        self.subscribed = threading.Event()
        self.client.on_subscribe = lambda *a: self.subscribed.set()

    def emit(self, obj):
        with self.lock:
            sys.stdout.write(json.dumps(obj) + "\n")
            sys.stdout.flush()

    def on_connect(self, client, userdata, flags, reason, props):
        # A new session with the broker: what came before it is unknown.
        self.types, self.values, self.seq = {}, {}, {}
        self.rebirth_asked = set()
        client.subscribe("spBv1.0/#", qos=1)

    def on_message(self, client, userdata, msg):
        parts = msg.topic.split("/")
        out = {"topic": msg.topic, "t": time.time(), "bytes": len(msg.payload), "errors": []}
        if len(parts) >= 3 and parts[1] == "STATE":
            out["kind"] = "STATE"
            out["state"] = msg.payload.decode(errors="replace")
            self.emit(out)
            return
        if len(parts) < 4:
            return
        kind, node = parts[2], parts[3]
        device = parts[4] if len(parts) > 4 else None
        out.update(kind=kind, node=node, device=device)
        p = self.pb.Payload()
        try:
            p.ParseFromString(msg.payload)
        except Exception as e:  # a payload the schema cannot read
            out["errors"].append(f"undecodable payload: {e}")
            self.emit(out)
            return
        errs = out["errors"]
        out["seq"] = p.seq if p.HasField("seq") else None
        if kind in ("NDATA", "DDATA", "DBIRTH", "DDEATH") and node not in self.seq:
            # A node whose NBIRTH this session has not seen (the host
            # connected after it): ask for a rebirth, as a host does, and
            # judge nothing of it until then.
            if node not in self.rebirth_asked:
                self.rebirth_asked.add(node)
                self.command({"rebirth": node}, wait=False)
            out["awaiting_rebirth"] = True
            self.emit(out)
            return
        out["timestamp"] = p.timestamp if p.HasField("timestamp") else None
        if out["timestamp"] is None:
            errs.append("no timestamp")
        key = (node, device)
        metrics = []
        if kind in ("NBIRTH", "DBIRTH"):
            if kind == "NBIRTH":
                self.types = {k: v for k, v in self.types.items() if k[0] != node}
                self.values = {k: v for k, v in self.values.items() if k[0] != node}
            types, values = {}, {}
            for m in p.metrics:
                d = m.datatype
                v = value_of(m, d)
                entry = {"name": m.name, "alias": m.alias if m.HasField("alias") else None,
                         "datatype": d, "value": v}
                if not m.HasField("name") or not m.HasField("datatype"):
                    errs.append(f"BIRTH metric without name or datatype: {entry}")
                if m.name != "bdSeq" and not m.HasField("alias"):
                    errs.append(f"BIRTH metric without alias: {m.name}")
                if FIELD_OF.get(d) != m.WhichOneof("value"):
                    errs.append(f"{m.name}: datatype {d} with {m.WhichOneof('value')}")
                if m.HasField("alias"):
                    if m.alias in types:
                        errs.append(f"alias {m.alias} twice")
                    types[m.alias] = (m.name, d)
                    values[m.alias] = v
                metrics.append(entry)
            self.types[key] = types
            self.values[key] = values
        elif kind in ("NDATA", "DDATA"):
            types = self.types.get(key)
            values = self.values.setdefault(key, {})
            if types is None:
                errs.append(f"{kind} before its BIRTH")
                types = {}
            for m in p.metrics:
                a = m.alias if m.HasField("alias") else None
                name, d = types.get(a, (None, None))
                if name is None:
                    errs.append(f"unknown alias {a}")
                    continue
                if FIELD_OF.get(d) != m.WhichOneof("value"):
                    errs.append(f"{name}: datatype {d} with {m.WhichOneof('value')}")
                v = value_of(m, d)
                if values.get(a) == v:
                    errs.append(f"{name} unchanged ({v}) in {kind}")
                values[a] = v
                metrics.append({"name": name, "alias": a, "datatype": d, "value": v})
        else:
            for m in p.metrics:
                d = m.datatype if m.HasField("datatype") else None
                metrics.append({"name": m.name if m.HasField("name") else None, "alias": None,
                                "datatype": d, "value": value_of(m, d)})
            if kind == "NDEATH" and not any(m["name"] == "bdSeq" and m["datatype"] == 4 for m in metrics):
                errs.append("NDEATH without bdSeq (Int64)")
        out["metrics"] = metrics
        if kind != "NDEATH" and kind in ("NBIRTH", "NDATA", "DBIRTH", "DDATA", "DDEATH"):
            seq = out["seq"]
            if seq is None:
                errs.append("no seq")
            elif kind == "NBIRTH":
                if seq != 0:
                    errs.append(f"NBIRTH seq {seq}")
            elif node in self.seq and seq != (self.seq[node] + 1) % 256:
                errs.append(f"seq {seq} after {self.seq[node]}")
            if seq is not None:
                self.seq[node] = seq
        self.emit(out)

    def command(self, cmd, wait=True):
        """Publishes what `cmd` asks; `wait`: until it is out (not from
        paho's own thread, which sends it)."""
        g = self.args.group
        if "state" in cmd:
            body = json.dumps({"online": bool(cmd["state"]), "timestamp": int(time.time() * 1000)})
            self.client.publish(f"spBv1.0/STATE/{self.args.host_id}", body, qos=1, retain=True).wait_for_publish(5)
            return
        p = self.pb.Payload()
        p.timestamp = int(time.time() * 1000)
        if "rebirth" in cmd:
            m = p.metrics.add()
            m.name, m.datatype, m.boolean_value = "Node Control/Rebirth", 11, True
            topic = f"spBv1.0/{g}/NCMD/{cmd['rebirth']}"
        else:
            for spec in cmd["metrics"]:
                m = p.metrics.add()
                m.name = spec["name"]
                m.datatype = TYPES[spec["type"]]
                v = spec["value"]
                if spec["type"] == "Boolean":
                    m.boolean_value = bool(v)
                elif spec["type"] == "Bytes":
                    m.bytes_value = bytes.fromhex(v)
                elif m.datatype in LONG_TYPES:
                    m.long_value = v & (1 << 64) - 1
                else:
                    m.int_value = v & 0xFFFFFFFF
            topic = f"spBv1.0/{g}/DCMD/{cmd['dcmd']}/controller"
        info = self.client.publish(topic, p.SerializeToString(), qos=0)
        if wait:
            info.wait_for_publish(5)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--group", required=True)
    ap.add_argument("--host-id", default="")
    ap.add_argument("--username", default="")
    ap.add_argument("--password", default="")
    args = ap.parse_args()
    host = Host(args, compile_proto())
    host.client.connect("127.0.0.1", args.port, keepalive=30)
    host.client.loop_start()
    if not host.subscribed.wait(10):
        sys.exit("no SUBACK from the broker within 10 s")
    host.emit({"ready": True})
    for line in sys.stdin:
        line = line.strip()
        if line:
            host.command(json.loads(line))
            host.emit({"done": json.loads(line)})
    host.client.loop_stop()
    host.client.disconnect()


if __name__ == "__main__":
    main()
