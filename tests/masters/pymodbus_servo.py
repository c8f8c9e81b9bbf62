"""A master we did not write (pymodbus) drives the simulator on the servo map (seed 004), with
pymodbus's RTU framer and then with its ASCII framer, the framing chosen as the manual says:
P□600 (0258h) written, saved (0x200F = 2) and taking effect at the restart 0541h = 1.

In each framing: the parameters P□304 (0130h, r/min), P□601 (0259h) and P□602 (025Ah) read and
written; exceptions (02, 03, 04) with the state read back unchanged; a broadcast write carried
out and never answered; servo-on through the communication IO 0451h; a position data group
(0600h-0607h) started by POS-START, followed in 05F0h until it ends, the actual position
05F2h-05F3h (low word first) on the target and the simulated rotor on a cam switch there (the
inputs 042Eh); a speed jog (0528h) at P□304; the communication timeout P□602 (alarm 30 current
in 044Ah and recorded in 0400h, moves refused, 0521h = 1 clears it). Then the manual's printed frames
(seed 004 §6.3), sent byte for byte past pymodbus's framer, and their answers checked byte for
byte. The run ends as it started: RTU, P□304 600 r/min, servo off.

Usage: pymodbus_servo.py ENDPOINT   where ENDPOINT is a pseudo-terminal path or HOST:PORT of
`hal-sim --map servo --switch ext1:pnp:3195:to=3205 --switch ext2:pnp:-1605:to=-1595` (the same
bytes on either: RTU frames, then ASCII lines). The two cams, around 3200 and -1600 full steps
from power-up (the resolution 0x600C is 0: full steps), are where the groups' moves end: the
drive's open loop reports the commanded position, the cams the simulated rotor's. Prints one
line per check and 'pymodbus_servo: N passed, M failed'; exits non-zero on any failure.
"""

import socket
import sys
import time

import serial
from master import check, connect, finish, is_tcp
from pymodbus import FramerType
from pymodbus.exceptions import ModbusException

ENDPOINT = sys.argv[1]
DEV = 1
WHERE = "tcp" if is_tcp(ENDPOINT) else "pty"
client = None


# -- pymodbus requests, an error or a lost answer reported as a value ---------------------------


def answer(request):
    """The reply of a pymodbus request: the registers (reads), 0 (writes), the exception code,
    or 'no answer'."""
    try:
        r = request()
    except ModbusException as e:
        return f"no answer ({e})"
    if r.isError():
        return getattr(r, "exception_code", "error")
    return list(r.registers) if hasattr(r, "registers") and r.function_code in (3, 4) else 0


def read(addr, n=1):
    return answer(lambda: client.read_holding_registers(addr, count=n, device_id=DEV))


def write(addr, value):
    return answer(lambda: client.write_register(addr, value & 0xFFFF, device_id=DEV))


def writes(addr, values):
    return answer(lambda: client.write_registers(addr, [v & 0xFFFF for v in values], device_id=DEV))


def s32(words):
    """A signed 32-bit value from two registers, low word first (§6.4)."""
    if not isinstance(words, list) or len(words) != 2:
        return None
    v = words[0] | (words[1] << 16)
    return v - (1 << 32) if v >= 1 << 31 else v


def words32(v):
    v &= 0xFFFFFFFF
    return [v & 0xFFFF, v >> 16]


def nothing_came(seconds=0.3):
    """True if no byte arrives on pymodbus's connection within `seconds` (nothing answered)."""
    time.sleep(seconds)
    line = client.socket
    if isinstance(line, socket.socket):
        try:
            line.recv(256, socket.MSG_PEEK | socket.MSG_DONTWAIT)  # bytes, or b"": closed
            return False
        except BlockingIOError:
            return True
    return line.in_waiting == 0


def wait_for(what, expected, timeout):
    """Polls read `what` until it returns `expected`; the last value read."""
    end = time.time() + timeout
    value = what()
    while value != expected and time.time() < end:
        time.sleep(0.02)
        value = what()
    return value


def on_cam(cam):
    """Whether input `cam` (1-7) is active (042Eh-042Fh, bit k IN k+1); None if unread."""
    v = s32(read(0x042E, 2))
    return None if v is None else bool(v >> (cam - 1) & 1)


# -- the drive through pymodbus -----------------------------------------------------------------


def suite(tag, p600, target, cam):
    """Parameters, exceptions, broadcast, servo-on, a data group, a jog and the communication
    timeout through pymodbus's framer of `tag`; the group moves to `target` (absolute), where
    the rotor actuates the cam switch on input `cam` (1-7)."""
    # Parameters at their factory values (P□600 as the framing in force), written, read back.
    check(f"{tag} P□304 (0130h) reads 600 r/min", read(0x0130) == [600], read(0x0130))
    check(f"{tag} P□600 (0258h) reads 0x{p600:02X}", read(0x0258) == [p600], read(0x0258))
    check(f"{tag} P□601, P□602 (0259h-025Ah) read 1, 0", read(0x0259, 2) == [1, 0], read(0x0259, 2))
    check(f"{tag} P□304 = 900", write(0x0130, 900) == 0 and read(0x0130) == [900], read(0x0130))
    # The address is taken at the next power-up: the drive still answers at 1.
    check(f"{tag} P□601 = 5 reads back at address 1", write(0x0259, 5) == 0 and read(0x0259) == [5])
    check(f"{tag} P□601 = 1 again", write(0x0259, 1) == 0 and read(0x0259) == [1])
    check(f"{tag} P□602 = 3, then 0", write(0x025A, 3) == 0 and read(0x025A) == [3] and write(0x025A, 0) == 0)

    # Exceptions change nothing.
    def state():
        return [read(0x0130), read(0x01F7), read(0x0258, 3), read(0x0451), read(0x0600, 8)]

    before = state()
    for name, got, code in [
        ("P□601 = 0 (0259h)", write(0x0259, 0), 3),
        ("reserved parameter 0100h = 1", write(0x0100, 1), 4),
        ("read of 0700h (no such register)", read(0x0700), 2),
        ("write of 0700h", write(0x0700, 1), 2),
        ("0451h = 2 (/P-CON: the drive has no P/PI switch)", write(0x0451, 2), 3),
    ]:
        check(f"{tag} {name} refused ({code:02})", got == code, got)
    check(f"{tag} reserved 0100h reads 0", read(0x0100) == [0], read(0x0100))
    check(f"{tag} nothing changed", state() == before)

    # Broadcast: carried out, never answered; read back at address 1.
    client.write_register(0x0130, 750, device_id=0, no_response_expected=True)
    check(f"{tag} broadcast P□304 = 750: no answer", nothing_came())
    check(f"{tag} broadcast carried out (read at address 1)", read(0x0130) == [750], read(0x0130))

    # Servo-on through the communication IO.
    check(f"{tag} 0457h: servo off (1)", read(0x0457) == [1], read(0x0457))
    check(f"{tag} 0451h = 1 (/SON)", write(0x0451, 1) == 0 and read(0x0457) == [2], read(0x0457))

    # Group 0: absolute `target` at 1500 r/min, no condition, started by POS-START (bit 13).
    group = words32(target) + [1500, 0, 0, 0, 0, 1]
    check(f"{tag} group 0 (0600h-0607h) = {group}", writes(0x0600, group) == 0 and read(0x0600, 8) == group)
    at0 = s32(read(0x05F2, 2))
    # 042Eh shows the inputs that have a function: the cam's input a touch probe (21, 22), which
    # captures a position and does nothing else.
    function = 0x21BA + cam - 1
    check(f"{tag} IN{cam} function = {20 + cam} (touch probe)", write(function, 20 + cam) == 0)
    check(f"{tag} IN{cam} (042Eh): the rotor is not on the cam at {target}", on_cam(cam) is False)
    check(f"{tag} 0451h = 0x2001 (/SON + /POS-START)", write(0x0451, 0x2001) == 0)
    check(f"{tag} 05F0h: group 0 running", read(0x05F0) == [0], read(0x05F0))
    check(f"{tag} 05F0h: 0xFFFF once the move ends", wait_for(lambda: read(0x05F0), [0xFFFF], 10) == [0xFFFF])
    at = s32(read(0x05F2, 2))
    check(f"{tag} 05F2h-05F3h (low word first) on the target {target}", at == target, f"from {at0} to {at}")
    check(f"{tag} IN{cam} (042Eh): the simulated rotor stands on the cam at {target}", on_cam(cam) is True)
    check(f"{tag} /POS-START released", write(0x0451, 1) == 0)

    # Speed jog at P□304 (750 r/min, broadcast above) while bit 0 is set.
    check(f"{tag} 0528h = 0x8001 (JOG+)", write(0x0528, 0x8001) == 0)
    time.sleep(0.3)
    speed = s32(read(0x0420, 2))
    check(f"{tag} 0420h: jogging at P□304 (750 r/min)", speed == 750, speed)
    check(f"{tag} 0528h = 0x8000 (jog stop)", write(0x0528, 0x8000) == 0)
    check(f"{tag} at rest (0457h = 2)", wait_for(lambda: read(0x0457), [2], 3) == [2], read(0x0457))
    at1 = s32(read(0x05F2, 2))
    check(f"{tag} the jog moved the axis forward", at1 is not None and at1 > at, f"{at} -> {at1}")
    check(f"{tag} and the rotor off the cam", on_cam(cam) is False)

    # Communication timeout: P□602 = 5 (500 ms), a jog, 1 s of silence.
    check(f"{tag} 0520h = 1 empties the alarm history", write(0x0520, 1) == 0 and read(0x0400) == [0], read(0x0400))
    check(f"{tag} P□602 = 5", write(0x025A, 5) == 0 and read(0x025A) == [5])
    check(f"{tag} 0528h = 0x8001 (JOG+)", write(0x0528, 0x8001) == 0)
    time.sleep(1.0)
    check(f"{tag} timeout: 044Ah (current alarm) = 30", read(0x044A) == [30], read(0x044A))
    check(f"{tag} timeout: 0400h (history) = 30", read(0x0400, 2) == [30, 0], read(0x0400, 2))
    check(f"{tag} timeout: the axis stopped", s32(read(0x0420, 2)) == 0, read(0x0420, 2))
    at2 = s32(read(0x05F2, 2))
    check(f"{tag} jog bits cleared (0528h = 0x8000)", write(0x0528, 0x8000) == 0)
    check(f"{tag} jog refused while alarm 30 is current (04)", write(0x0528, 0x8001) == 4)
    check(f"{tag} POS-START refused while alarm 30 is current (04)", write(0x0451, 0x2001) == 4)
    time.sleep(0.1)
    check(f"{tag} nothing moved", s32(read(0x05F2, 2)) == at2)
    check(f"{tag} P□602 = 0, 0521h = 1 clears the alarm", write(0x025A, 0) == 0 and write(0x0521, 1) == 0)
    check(f"{tag} 044Ah = 0, 0400h keeps 30", read(0x044A) == [0] and read(0x0400) == [30])

    # As it started: jog and servo off, P□304 600 r/min.
    check(f"{tag} 0528h = 0, 0451h = 0", write(0x0528, 0) == 0 and write(0x0451, 0) == 0)
    check(f"{tag} servo off (0457h = 1)", wait_for(lambda: read(0x0457), [1], 3) == [1], read(0x0457))
    check(f"{tag} P□304 = 600", write(0x0130, 600) == 0 and read(0x0130) == [600])
    check(f"{tag} IN{cam} function = 0", write(function, 0) == 0 and read(function) == [0])


def switch(tag, p600):
    """P□600 = p600, saved, the drive restarted (0541h = 1); pymodbus's connection closed."""
    check(f"{tag} P□600 = 0x{p600:02X}", write(0x0258, p600) == 0 and read(0x0258) == [p600])
    check(f"{tag} save (0x200F = 2)", write(0x200F, 2) == 0)
    # The framing in force is the one read at power-up: this framer still talks.
    check(f"{tag} saved, the framing unchanged until the restart", read(0x0258) == [p600])
    got = wait_for(lambda: write(0x0541, 1), 0, 2)  # refused (04) while the save runs
    check(f"{tag} restart (0541h = 1)", got == 0, got)
    client.close()
    time.sleep(0.1)


# -- the manual's frames, byte for byte, past pymodbus ------------------------------------------


def crc(data):
    c = 0xFFFF
    for b in data:
        c ^= b
        for _ in range(8):
            c = (c >> 1) ^ 0xA001 if c & 1 else c >> 1
    return bytes([c & 0xFF, c >> 8])


def lrc(data):
    return (-sum(data)) & 0xFF


def rtu(text):
    """An RTU frame from hex bytes, its CRC appended."""
    b = bytes.fromhex(text)
    return b + crc(b)


def line(text):
    """An ASCII line from hex bytes: ':', upper-case hex, LRC, CR LF."""
    b = bytes.fromhex(text)
    return b":" + (b + bytes([lrc(b)])).hex().upper().encode() + b"\r\n"


class Raw:
    """The endpoint opened past pymodbus: bytes written as given, the answer as it comes."""

    def __init__(self):
        if is_tcp(ENDPOINT):
            host, port = ENDPOINT.rsplit(":", 1)
            self.s = socket.create_connection((host, int(port)), timeout=2)
            self.s.settimeout(0.02)
            self.serial = None
        else:
            self.serial = serial.Serial(ENDPOINT, 9600, timeout=0.02)

    def _read(self):
        if self.serial:
            return self.serial.read(512)
        try:
            return self.s.recv(512)
        except socket.timeout:
            return b""

    def ask(self, data, ascii_line=False, wait=1.0):
        """Sends `data`; what comes back: an ASCII line to its LF, an RTU frame to a silence of
        50 ms, or nothing in `wait` seconds."""
        (self.serial.write if self.serial else self.s.sendall)(data)
        got, end, quiet = b"", time.time() + wait, None
        while time.time() < end:
            chunk = self._read()
            if chunk:
                got += chunk
                quiet = time.time() + 0.05
                if ascii_line and got.endswith(b"\n"):
                    break
            elif quiet and time.time() > quiet and not ascii_line:
                break
        return got

    def close(self):
        (self.serial or self.s).close()


def show(data):
    """Bytes as the manual prints them: an ASCII line as text, an RTU frame in hex."""
    if data.startswith(b":"):
        return data.decode(errors="replace").replace("\r\n", "\\r\\n")
    return data.hex(" ").upper() or "nothing"


def rtu_reply(frame):
    """(address, function, data) of a well-formed RTU frame (CRC right), else None."""
    if len(frame) < 5 or crc(frame[:-2]) != frame[-2:]:
        return None
    return frame[0], frame[1], frame[2:-2]


def ascii_reply(text):
    """(address, function, data) of a well-formed ASCII line (upper case, LRC right), else None."""
    if not (text.startswith(b":") and text.endswith(b"\r\n")):
        return None
    digits = text[1:-2]
    if digits != digits.upper() or len(digits) % 2:
        return None
    try:
        b = bytes.fromhex(digits.decode())
    except ValueError:
        return None
    if len(b) < 3 or lrc(b[:-1]) != b[-1]:
        return None
    return b[0], b[1], b[2:-1]


def registers(reply, n):
    """The n registers of a well-formed read reply of node 1, else None."""
    if reply is None or reply[:2] != (1, 3) or reply[2][:1] != bytes([2 * n]) or len(reply[2]) != 1 + 2 * n:
        return None
    data = reply[2][1:]
    return [int.from_bytes(data[i : i + 2], "big") for i in range(0, 2 * n, 2)]


def manual(tag, frames, encode, parse, ascii_line):
    """§6.3's frames of one framing: the 0200h-0201h read (the drive's values), the write
    0200h = 0064h (echoed if P□512 takes it, else 04), the 0101h.. read (reserved: zeros)."""
    global client
    p512 = read(0x0200, 2)
    p513 = read(0x0201)
    inputs = read(0x21BA, 7)
    client.close()
    raw = Raw()
    (read200, write200, read_other, other_addr, other_n) = frames
    got = raw.ask(read200, ascii_line)
    got = raw.ask(read200, ascii_line)
    check(f"{tag} {show(read200)}: 2 registers, the drive's {p512}", registers(parse(got), 2) == p512, show(got))
    got = raw.ask(write200, ascii_line)
    if got == write200:
        # P□512 takes 0064h: the echo is the request.
        check(f"{tag} {show(write200)} taken: the echo is the request, byte for byte", True, show(got))
        expected = [0x0064, p512[1]] if isinstance(p512, list) else None
    else:
        refusal = encode("01 86 04")
        check(f"{tag} {show(write200)} refused: {show(refusal)}", got == refusal, show(got))
        expected = p512
    got = raw.ask(read200, ascii_line)
    check(f"{tag} {show(read200)} again: {expected}", registers(parse(got), 2) == expected, show(got))
    got = raw.ask(read_other, ascii_line)
    values = [0] * other_n if other_addr == 0x0101 else p513
    ok = registers(parse(got), other_n) == values
    check(f"{tag} {show(read_other)}: {other_n} register(s), {values}", ok, show(got))
    if other_addr == 0x0101:
        zeros = encode("01 03 04 00 00 00 00")
        check(f"{tag} reserved, byte for byte: {show(zeros)}", got == zeros, show(got))
    raw.close()
    client = connect(ENDPOINT, FramerType.ASCII if ascii_line else FramerType.RTU)
    # P□512 as it was (if the write took, its inputs' functions go back too).
    if isinstance(p512, list) and read(0x0200, 2) != p512:
        check(f"{tag} P□512 = 0x{p512[0]:04X} again", write(0x0200, p512[0]) == 0 and read(0x0200, 2) == p512)
    check(f"{tag} the inputs' functions (0x21BA-0x21C0) as before", read(0x21BA, 7) == inputs, read(0x21BA, 7))


def unanswered(tag, data):
    """The other framing's request gets no answer."""
    raw = Raw()
    got = raw.ask(data, wait=0.3)
    raw.close()
    check(f"{tag} {show(data)} not answered", got == b"", show(got))


start = time.time()
client = connect(ENDPOINT)

rtu_tag = f"RTU/{WHERE}"
suite(rtu_tag, 0x01, 3200, 1)
manual(
    rtu_tag,
    (
        bytes.fromhex("01 03 02 00 00 02 C5 B3"),
        bytes.fromhex("01 06 02 00 00 64 89 99"),
        bytes.fromhex("01 03 01 01 00 02 94 37"),
        0x0101,
        2,
    ),
    rtu,
    rtu_reply,
    False,
)
ours = rtu("01 03 02 00 00 02")
check(f"{rtu_tag} the manual's frames' CRCs are ours", ours == bytes.fromhex("01 03 02 00 00 02 C5 B3"))

# To ASCII 8N1 9600 (P□600 digit 1 = 3), saved, restarted.
switch(rtu_tag, 0x31)
ascii_tag = f"ASCII/{WHERE}"
unanswered(ascii_tag, rtu("01 03 02 58 00 01"))
client = connect(ENDPOINT, FramerType.ASCII)
suite(ascii_tag, 0x31, -1600, 2)
manual(
    ascii_tag,
    (b":010302000002F8\r\n", b":01060200006493\r\n", b":010302010001F8\r\n", 0x0201, 1),
    line,
    ascii_reply,
    True,
)
check(f"{ascii_tag} the manual's lines' LRCs are ours", line("01 03 02 00 00 02") == b":010302000002F8\r\n")

# Back to RTU 8N1 9600, as the run started.
switch(ascii_tag, 0x01)
unanswered(rtu_tag, line("01 03 02 58 00 01"))
client = connect(ENDPOINT)
check(f"{rtu_tag} again: P□600 reads 0x01", read(0x0258) == [0x01], read(0x0258))
print(f"pymodbus_servo on {WHERE}: {time.time() - start:.1f} s")
finish(client, "pymodbus_servo")
