#!/usr/bin/env python3
"""Example insitud client (Python standard library only): arms the machine, runs a job, follows
its progress and prints the result.

    python3 docs/insitu_client.py config/jobs/scan_step_gauge.yaml --set scan.x_end_mm=0
    python3 docs/insitu_client.py JOB.yaml --host 127.0.0.1 --port 7450 --token SECRET

The job path is read by the daemon, relative to its jobs_dir. See docs/protocol.md.
"""
import argparse
import json
import socket
import sys


class Client:
    def __init__(self, host, port, timeout_s=600.0):
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        self.file = self.sock.makefile("rwb")
        self.next_id = 0
        self.events = []  # events that arrived while a call waited for its reply

    def _line(self):
        raw = self.file.readline()
        if not raw:
            raise ConnectionError("insitud closed the connection")
        return json.loads(raw)

    def call(self, cmd, **args):
        self.next_id += 1
        request = {"id": self.next_id, "cmd": cmd, **args}
        self.file.write((json.dumps(request) + "\n").encode())
        self.file.flush()
        while True:
            msg = self._line()
            if "event" in msg:
                self.events.append(msg)
                continue
            if not msg.get("ok"):
                err = msg.get("error", {})
                raise RuntimeError(f"{cmd}: {err.get('code')}: {err.get('message')}")
            return msg

    def event(self):
        return self.events.pop(0) if self.events else self._line()


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("job", help="job file path (on the daemon's machine, relative to its jobs_dir)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=7450)
    p.add_argument("--token", help="the daemon's token, if it has one")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = p.parse_args()

    c = Client(a.host, a.port)
    if a.token:
        c.call("auth", token=a.token)
    c.call("subscribe")
    c.call("arm")
    sets = dict(s.split("=", 1) for s in a.set)
    started = c.call("run", job=a.job, set=sets) if sets else c.call("run", job=a.job)
    job_id = started["job_id"]
    print(f"job {job_id} ({started['job']}) started")
    while True:
        e = c.event()
        if e.get("event") == "state":
            print(f"  state: {e['from']} -> {e['to']}" + (f" ({e['reason']})" if e.get("reason") else ""))
        elif e.get("event") == "progress" and e.get("job_id") == job_id:
            total = e["total"] or 1
            print(f"  {e['phase']}: {e['done']:g}/{e['total']:g} {e['unit']} "
                  f"({100.0 * e['done'] / total:.0f}%)")
        elif e.get("event") == "job" and e.get("job_id") == job_id and e["status"] == "queued":
            print(f"  queued, position {e['position']}")
        elif e.get("event") == "job" and e.get("job_id") == job_id and e["status"] not in (
                "running", "queued"):
            print(f"  job {e['status']}" + (f": {e['reason']}" if e.get("reason") else ""))
            break
    result = c.call("result", job_id=job_id)
    report = result.get("report") or {}
    for name, value in sorted(report.get("metrics", {}).items()):
        print(f"  {name} = {'n/a' if value is None else format(value, 'g')}")
    c.call("disarm")
    return 0 if result["result"]["status"] == "done" else 1


if __name__ == "__main__":
    sys.exit(main())
