"""A master we did not write (pymodbus) drives the simulator on the DS-CLS9 map (seed 002):
every command of the control command 0323, the axis doing what the manual's table says (read
back as the actual position 0126 and speed 0119), the soft limits on the enabled side only,
homing both ways with the offset, refusals with nothing changed, input functions given by
pseudo-inputs, the output and in-position settings, and a multi-segment program checked,
refused with its error segment, and run.

Usage: pymodbus_cls9.py ENDPOINT   where ENDPOINT is a pseudo-terminal path or HOST:PORT of
`hal-sim --map cls9 --switch ext1:pnp:40:to=44 --switch ext2:pnp:-120:below --switch
ext3:pnp:120` (a home cam from 40 to 44 full steps, the negative limit at -120, the positive at
120). Prints one line per check and 'N passed, M failed'; exits non-zero on any failure.
"""

import sys
import time

from master import check, connect, finish

ENDPOINT = sys.argv[1]
DEV = 1
client = connect(ENDPOINT)


def read(addr, n=1):
    r = client.read_holding_registers(addr, count=n, device_id=DEV)
    return None if r.isError() else list(r.registers)


def s16(w):
    return w - 0x10000 if w >= 0x8000 else w


def read32(addr):
    w = read(addr, 2)
    v = (w[0] << 16) | w[1]
    return v - (1 << 32) if v >= 1 << 31 else v


def write(addr, v):
    r = client.write_register(addr, v & 0xFFFF, device_id=DEV)
    return getattr(r, "exception_code", None) if r.isError() else 0


def write32(addr, v):
    v &= 0xFFFFFFFF
    r = client.write_registers(addr, [v >> 16, v & 0xFFFF], device_id=DEV)
    return getattr(r, "exception_code", None) if r.isError() else 0


def command(c):
    return write(323, c)


def settle(timeout=30):
    """Waits until 0109 says standing (2); the actual position."""
    end = time.time() + timeout
    while time.time() < end:
        if read(109) == [2]:
            return read32(126)
        time.sleep(0.05)
    return None


def speed_after(seconds):
    time.sleep(seconds)
    return s16(read(119)[0])


# Factory: 200 pulses a revolution, energised and standing, no alarm.
check("0104 resolution", read32(104) == 200, read32(104))
check("0108/0109 no alarm, standing", read(108, 2) == [0, 2], read(108, 2))
factory = [100, 100, 100, 100, 0, 1000, 1000, 1000, 1000, 1000]
check("0301-0310 the manual's factory values", read(301, 10) == factory, read(301, 10))
check("0420-0423 the manual's factory values", read(420, 4) == [101, 100, 100, 100], read(420, 4))

# 3200 pulses a revolution, ramps of 50 rev/s², runs at 5 rev/s, jogs at 2 rev/s.
check("0242 = 3200", write32(242, 3200) == 0 and read32(104) == 3200)
for reg, v in [(303, 50), (304, 50), (306, 500), (308, 200)]:
    check(f"{reg:04} = {v}", write(reg, v) == 0 and read(reg) == [v], read(reg))

# 1: absolute run (the direction from the target's sign).
write32(313, 16000)
check("1 absolute run", command(1) == 0)
check("absolute run ends on 0313", settle() == 16000, read32(126))
# A new target during the run takes effect.
write32(313, 48000)
command(1)
time.sleep(0.3)
write32(313, 8000)
check("absolute run re-targeted on line", settle() == 8000, read32(126))

# 2: relative run by 0313 (negative: backwards); refused while moving.
write32(313, -4000)
check("2 relative run", command(2) == 0)
check("relative run refused while moving (04)", command(2) == 4)
check("relative run by the distance", settle() == 4000, read32(126))

# 3: velocity run at 0307, its sign the direction; a new 0307 changes the speed; 6 stops.
write(307, -300)
check("3 velocity run", command(3) == 0)
check("runs at 0307 (-3 rev/s)", speed_after(0.5) == -300)
write(307, 150)
check("0307 during the run changes the speed", speed_after(0.5) == 150)
check("6 decelerating stop", command(6) == 0 and settle() is not None)
check("standing, speed 0", read(119) == [0])

# 4 / 5: jogs at 0308 until a stop; 7 emergency stop.
check("4 jog +", command(4) == 0 and speed_after(0.3) == 200)
check("7 emergency stop", command(7) == 0 and settle(2) is not None)
check("5 jog -", command(5) == 0 and speed_after(0.3) == -200)
check("6 stop", command(6) == 0 and settle(2) is not None)

# 8: set the position to 0321, only standing.
write32(321, 0)
check("8 set position", command(8) == 0 and read32(126) == 0, read32(126))
command(4)
time.sleep(0.1)
check("8 refused while moving (04)", command(8) == 4 and read32(126) != 0)
command(6)
settle()

# Soft limits: the positive one stops a run on it; the negative side, off, lets a run by.
write32(313, 0)
command(1)
settle()
write32(317, 8000)
write32(319, -8000)
check("0324 = 1 (positive on)", write(324, 1) == 0)
write32(313, 20000)
command(1)
check("positive soft limit stops the run on it", settle() == 8000, read32(126))
write32(313, -12000)
command(1)
check("negative side off: the run goes by -8000", settle() == -12000, read32(126))
write(324, 3)
write32(313, 0)
command(1)
settle()
command(5)
check("jog towards the enabled negative limit ends on it", settle() == -8000, read32(126))
write(324, 0)

# Refusals change nothing.
before = read(301, 8)
check("0102 does not exist (02)", write(102, 1) == 2)
check("a half of 0313 alone (02)", write(313, 1) == 2)
check("resolution 300 (03)", write32(242, 300) == 3)
check("command 20 (03)", command(20) == 3)
check("state unchanged", read(301, 8) == before and read32(104) == 3200)

# Homing (12): the home cam between 40 and 44 full steps (640-704 pulses); inputs: home EXT1,
# negative limit EXT2, positive EXT3, all actuated high (pnp).
check("0x216C switches", write(0x216C, 0x0321) == 0 and write(0x216D, 7) == 0)
write(309, 100)
write(310, 10)
write32(311, 1000)
for direction, name in [(0, "clockwise"), (1, "counter-clockwise")]:
    write32(321, 0)
    command(8)
    write(305, direction)
    check(f"12 homing {name}", command(12) == 0)
    at = settle(60)
    # Standing on the cam's edge found at the creep speed: the home reads as 0311.
    check(f"homing {name}: the home reads as 0311", at is not None and abs(at - 1000) <= 16, at)
    check(f"0305 reads {direction}", read(305) == [direction])

# Inputs 0400-0416: IN4 jogs + and IN5 stops, given by their pseudo-inputs 0413 and 0414.
check("0403 = 4, 0404 = 6", write(403, 4) == 0 and write(404, 6) == 0)
check("0400 = 23 (no such function) refused (03)", write(400, 23) == 3 and read(400) == [0])
check("0413 = 1: IN4 jogs +", write(413, 1) == 0 and speed_after(0.3) == 200)
check("0414 = 1: IN5 stops", write(414, 1) == 0 and settle(3) is not None)
check("0410-0416 read back", read(410, 7) == [0, 0, 0, 1, 1, 0, 0], read(410, 7))
check("0413, 0414 released", write(413, 0) == 0 and write(414, 0) == 0)

# Outputs 0420-0430 and the in-position window 0247.
check("0420 = 101 (alarm)", write(420, 101) == 0 and read(420) == [101], read(420))
check("0421 = 99 refused (03)", write(421, 99) == 3 and read(421) == [100], read(421))
check("0428, 0429, 0430", write(428, 1) == 0 and write(429, 3) == 0 and write(430, 2) == 0)
check("0247 = 20 (two words)", write32(247, 20) == 0 and read32(247) == 20, read32(247))

# Multi-segment program (1024-1536): to 1000, 100 ms, three times 200 back, end (between the
# home cam the homing left the axis on and the positive limit); segment 2 an unknown code. The check names segment 2, a start of it
# is refused and nothing moves.
write32(321, 0)
command(8)
program = [54, 500, 61, 50, 62, 50, 1, 0, 1000, 65, 5, 100, 2, 0xFFFF, 0xFF38, 66, 3, 5, 100, 3, 0, 0, 100]
r = client.write_registers(1024, program, device_id=DEV)
check("1024.. program written and read back", not r.isError() and read(1024, len(program)) == program)
check("0327 = 2, 0323 = 14: segment 2 in error", write(327, 2) == 0 and command(14) == 0 and read(176) == [2], read(176))
check("0328 = 1, 0323 = 16 refused (04), 0178 = 0", write(328, 1) == 0 and command(16) == 4 and read(178) == [0])
check("nothing moved", settle() == 0, read32(126))
check("0328 = 0 still refused: every segment of 0327 is checked", write(328, 0) == 0 and command(16) == 4)
check("0327 = 1, 0323 = 16: segment 1 runs", write(327, 1) == 0 and command(16) == 0 and read(178) == [1], read(178))
check("program writes refused while it runs (04)", write(1024, 54) == 4)
deadline = time.time() + 30
while time.time() < deadline and read(178) != [0]:
    time.sleep(0.05)
check("segment 1 ends at 1000 - 3 x 200", read(178) == [0] and read32(126) == 400, read32(126))
check("0174 with no select input", read(174) == [0], read(174))

finish(client, "pymodbus, DS-CLS9 map")
