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


def connect(endpoint):
    """An RTU client of the drive at `endpoint`; exits with 2 if it cannot connect."""
    if ":" in endpoint and not endpoint.startswith("/"):
        host, port = endpoint.rsplit(":", 1)
        client = ModbusTcpClient(host, port=int(port), framer=FramerType.RTU, timeout=2)
    else:
        client = ModbusSerialClient(endpoint, framer=FramerType.RTU, baudrate=9600, timeout=2)
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
