"""What the pymodbus scripts share: the connection to the simulator (a pseudo-terminal path, or
HOST:PORT for raw RTU frames over TCP), the checks and their summary."""

import sys

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient

results = []


def check(name, ok, detail=""):
    """Records and prints one check."""
    results.append(ok)
    print(f"{'ok  ' if ok else 'FAIL'} {name} {detail}")


def is_tcp(endpoint):
    """True for HOST:PORT, false for a pseudo-terminal's path."""
    return ":" in endpoint and not endpoint.startswith("/")


def connect(endpoint, framer=FramerType.RTU):
    """A client of the drive at `endpoint` with pymodbus's RTU framer (or `framer`: ASCII, over
    the pseudo-terminal or TCP alike); exits with 2 if it cannot connect."""
    if is_tcp(endpoint):
        host, port = endpoint.rsplit(":", 1)
        client = ModbusTcpClient(host, port=int(port), framer=framer, timeout=2)
    else:
        client = ModbusSerialClient(endpoint, framer=framer, baudrate=9600, timeout=2)
    if not client.connect():
        print(f"cannot connect to {endpoint}")
        sys.exit(2)
    return client


def finish(client, name):
    """Closes the client, prints the summary and exits non-zero on any failed check."""
    client.close()
    passed, failed = results.count(True), results.count(False)
    print(f"{name}: {passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)
