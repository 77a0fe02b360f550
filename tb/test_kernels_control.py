"""Bench of the non-image kernels in one ``kernels`` top: MergeSorter (docs/reconos.md),
PidController (docs/kernels.md), InverseKinematics (docs/reconos.md), BallControl
(docs/kernels.md).

Golden models: Python's ``sorted``; the AVR221 model of tb/models/pid.py (checked against the
spec's test vectors in tb/test_kernels_models.py); the ap_fixed model of
tb/models/inverse_kinematics.py. Every stream port runs under random idle and backpressure
with a scoreboard, and each kernel's cycle budget of the issue is asserted at full rate:
2048 values sorted in <= 25,000 cycles, one PID update per clock, <= 200 cycles per
inverse-kinematics solution.
"""

import os

import cocotb
from cocotb.triggers import ClockCycles, RisingEdge, with_timeout
from cocotbext.axi import AxiStreamFrame

from tb.harness import amount, cocotb_bench
from tb.models import inverse_kinematics as ik_model
from tb.models.ball_control import (BallControlModel, RollingBall, leg_words, servo_pulse,
                                    tilt_radians, word_tilts)
from tb.models.pid import AvrPid, FirstOrderPlant
from tb.streams import count_pulses, random_pauses

from .kernels_control_tb import CLOCK_NS, ControlTB, int16, pid_word, run_ik, run_pid, run_sort

KERNELS = {
    "sort": dict(kind="sort", block_size=2048),
    "pid": dict(kind="pid"),
    "ik": dict(kind="inverse_kinematics", lanes=16),
    "ball": dict(kind="ball_control"),
    # a 250 kHz kernel clock keeps a 20 ms period at 5,000 cycles
    "servo": dict(kind="servo_pwm", clock_hz=250_000),
}

CONFIGS = {"control": dict(kernels=KERNELS)}

#: tilts of leg 2 whose arm angle is table entry 1, 4, 8 and 15, and of leg 4 whose angle is
#: entry 2033, 2037, 2040 and 2043 (found with the model): the search's first and last
#: addresses hold entries 0 to lanes - 1 and the last lanes, so these fail if the search
#: starts before the plate joint's position has left the setup pipeline, or if the result
#: is taken before the last entries have reached the lanes' minima and their reduction
EDGE_WORDS = [0x1F309FEA, 0x21529E52, 0x21189E22, 0x1E949FAA,
              0xF6A62B4, 0xFD6574C, 0xF3C6334, 0xF066554]

# Verilator runs it in make test-full only (its build and run would add minutes to make test)
test_kernels = cocotb_bench("kernels", CONFIGS, long=[("control", "verilator")])

SIM = os.environ.get("ROSGATE_SIM", "")


@cocotb.test()
async def all_kernels_under_idle_and_backpressure(dut):
    """Sort blocks (random values mixed with repeats; make test-full adds an all-random and
    an all-duplicates block), a PID sequence (the spec's vectors, then random pairs) and
    inverse-kinematics requests (the ReconROS client's, tilts of +-20 degrees) concurrently,
    30 % idle, 30 % backpressure; every output equals its golden model."""
    tb = ControlTB(dut)
    await tb.reset()
    tb.set_pauses(0.3, 0.3)
    await tb.load_pid(256, 64, 32)
    rng = tb.rng
    # one block of random values mixed with repeats of 0, 7 and 0xFFFFFFFF; make test-full
    # also sorts an all-random and an all-duplicates block
    repeats = (0, 7, 0xFFFFFFFF)
    mixed = [rng.randrange(1 << 32) if rng.random() < 0.5 else rng.choice(repeats)
             for _ in range(2048)]
    blocks = [mixed] + amount([], [[rng.randrange(1 << 32) for _ in range(2048)],
                                   [rng.choice(repeats) for _ in range(2048)]])
    vector = [(1000, pv) for pv in (0, 100, 250, 400, 600, 800, 950, 1000, 1020, 1000)]
    pairs = vector + [(rng.randrange(-2000, 2000), rng.randrange(-2000, 2000))
                      for _ in range(300)]
    count = amount(24, 60) if SIM == "icarus" else amount(200, 1000)
    ik_words = [w for w in (ik_model.client_word(i) for i in range(count)) if w & 7 < 6]
    twenty = round(20 * 256)
    ik_words += [ik_model.encode_input(a, b, leg) for leg in range(6)
                 for a, b in ((twenty, -twenty), (-twenty, twenty), (8191, -8192))]
    tasks = [cocotb.start_soon(run_sort(tb, blocks)), cocotb.start_soon(run_pid(tb, pairs)),
             cocotb.start_soon(run_ik(tb, ik_words))]
    for task in tasks:
        await with_timeout(task, 400_000 * CLOCK_NS, "ns")
    await tb.wait_words("ik", len(ik_words), 400 * len(ik_words))

    model = AvrPid(256, 64, 32)
    want = [model.update(sp, pv) for sp, pv in pairs]
    got = [int16(w) for w in tb.ports["pid"].words()]
    assert got[:10] == [755, 1180, 1543, 1843, 2030, 2130, 2012, 1937, 1895, 1945], got[:10]
    assert got == want, "PID output differs from the AVR221 model"

    got = tb.ports["ik"].words()
    want = [ik_model.solve(w) for w in ik_words]
    bad = [(hex(w), hex(g), hex(e)) for w, g, e in zip(ik_words, got, want) if g != e]
    assert not bad and len(got) == len(want), f"{len(bad)} IK solutions differ: {bad[:4]}"
    assert tb.err_leg == 0 and tb.sort_errors == {"short": 0, "long": 0}


@cocotb.test()
async def bad_input_is_flagged_and_dropped(dut):
    """IK requests naming leg 6 or 7 are dropped with ``err_leg``, the next ones answered;
    a short and a long sort block are padded and cut with their error pulses, the next block
    sorted."""
    tb = ControlTB(dut)
    await tb.reset()
    tb.set_pauses(0.2, 0.2)
    good = [ik_model.client_word(i) for i in (1, 2)]
    await run_ik(tb, [good[0] | 7, good[0], (good[1] & ~7) | 6, good[1]])
    await tb.wait_words("ik", 2, 2000)
    await ClockCycles(dut.aclk, 400)
    got = tb.ports["ik"].words()
    assert got == [ik_model.solve(w) for w in good], [hex(g) for g in got]
    assert tb.err_leg == 2
    rng = tb.rng
    short = [rng.randrange(1000) for _ in range(40)]
    long_ = [rng.randrange(1000) for _ in range(70)]
    ok = [rng.randrange(1 << 32) for _ in range(64)]
    await run_sort(tb, [short, long_, ok], [64, 64, 64])
    assert tb.sort_errors == {"short": 1, "long": 1}


@cocotb.test()
async def full_rate_budgets(dut):
    """No idle or backpressure: 2048 values in <= 25,000 cycles; 500 PID updates in 500 +
    latency cycles (one per clock); an IK solution every <= 200 cycles."""
    tb = ControlTB(dut)
    await tb.reset()
    tb.set_pauses(0, 0)
    await tb.load_pid(128, 16, 64)
    rng = tb.rng
    port = tb.ports["sort"]
    block = [rng.randrange(1 << 32) for _ in range(2048)]
    start = tb.cycle
    await port.source.send(AxiStreamFrame(b"".join(v.to_bytes(4, "little") for v in block)))
    await tb.wait_words("sort", 2048, 30_000)
    first_in = start
    sort_cycles = port.sink.packets[0].cycles[-1] - first_in
    assert [d for d, _, _ in port.sink.packets[0].beats] == sorted(block)
    assert sort_cycles <= 25_000, sort_cycles

    pairs = [(rng.randrange(-3000, 3000), rng.randrange(-3000, 3000)) for _ in range(500)]
    pid = tb.ports["pid"]
    await run_pid(tb, pairs)
    cycles = pid.sink.packets[0].cycles
    pid_span = cycles[-1] - cycles[0] + 1
    model = AvrPid(128, 16, 64)
    assert [int16(w) for w in pid.words()] == [model.update(*p) for p in pairs]
    assert pid_span == len(pairs), f"{len(pairs)} PID updates took {pid_span} cycles"

    words = [ik_model.client_word(i) for i in range(3, 40) if ik_model.client_word(i) & 7 < 6]
    words += EDGE_WORDS
    ik = tb.ports["ik"]
    await run_ik(tb, words)
    await tb.wait_words("ik", len(words), 250 * len(words))
    ends = [c for p in ik.sink.packets for c in p.cycles]
    per = (ends[-1] - ends[0]) / (len(ends) - 1)
    assert ik.words() == [ik_model.solve(w) for w in words]
    assert per <= 200, per
    tb.dut._log.info("full rate: sort 2048 in %d cycles, %d PID updates in %d cycles, IK %.1f "
                     "cycles per solution", sort_cycles, len(pairs), pid_span, per)


@cocotb.test()
async def pid_closed_loop_first_order_plant(dut):
    """The PID drives a first-order plant (tb/models/pid.py) to a set point step and back;
    each output equals the model's, and the plant settles within 2 % of the set point
    (P = 2, I = 0.25, D = 0: the model settles in under 100 updates)."""
    tb = ControlTB(dut)
    await tb.reset()
    tb.set_pauses(0, 0.3)
    await tb.load_pid(256, 32, 0)
    model = AvrPid(256, 32, 0)
    plant_hw, plant_model = FirstOrderPlant(), FirstOrderPlant()
    port = tb.ports["pid"]
    trace = []
    for step in range(400):
        sp = 2000 if step < 250 else -500
        y = plant_hw.y
        before = sum(len(p.beats) for p in port.sink.packets)
        await port.source.send(AxiStreamFrame(pid_word(sp, y).to_bytes(4, "little")))
        await tb.wait_words("pid", before + 1, 200)
        u = int16(port.words()[-1])
        assert u == model.update(sp, plant_model.y), f"step {step}: {u}"
        plant_hw.step(u)
        plant_model.step(u)
        trace.append((sp, y, u))
    for sp, target_end in ((2000, 249), (-500, 399)):
        y = trace[target_end][1]
        assert abs(y - sp) <= abs(sp) * 0.02, f"plant at {y} for set point {sp}"


async def ball_update(tb, raw_x, raw_y):
    """One touch sample through BallControl: its six words."""
    port = tb.ports["ball"]
    before = len(port.words())
    word = (raw_x & 0xFFF) | ((raw_y & 0xFFF) << 16)
    await port.source.send(AxiStreamFrame(word.to_bytes(4, "little")))
    await tb.wait_words("ball", before + 6, 2000)
    return port.words()[before:before + 6]


@cocotb.test()
async def ball_control_closed_loop(dut):
    """BallControl balances a ball dropped 90 mm and 60 mm off centre on the rolling-ball
    plant (tb/models/ball_control.py), 30 % idle and backpressure: every sample's six words
    equal the fixed-point model's, one packet per sample, and the ball is within 3 mm of the
    centre after 200 samples (6 s at 30 ms); the panel's extremes and a jump of the touch
    reading are taken the same way."""
    tb = ControlTB(dut)
    await tb.reset()
    tb.set_pauses(0.3, 0.3)
    model = BallControlModel()
    ball = RollingBall(90.0, -60.0)
    for n in range(200):
        raw = ball.touch()
        words = await ball_update(tb, *raw)
        assert words == leg_words(*model.update(*raw)), f"sample {n}: {[hex(w) for w in words]}"
        alpha, beta = (tilt_radians(t) for t in word_tilts(words[0]))
        ball.step(alpha, beta, 0.03)
    radius = (ball.x ** 2 + ball.y ** 2) ** 0.5
    dut._log.info("ball at (%.2f, %.2f) mm after 200 samples", ball.x, ball.y)
    assert radius < 3.0, f"ball {radius:.1f} mm from the centre after 6 s"
    for raw in ((-2048, 2047), (2047, -2048), (0, 0), (1500, -1500)):
        words = await ball_update(tb, *raw)
        assert words == leg_words(*model.update(*raw))
    packets = tb.ports["ball"].sink.packets
    assert len(packets) == 204 and all(len(p.beats) == 6 for p in packets)


async def pwm_pulses(dut, periods):
    """High time in cycles of each channel's pulse in each of the next ``periods`` periods,
    from one ``period_start`` on."""
    while dut.servo_period_start.value != 1:
        await RisingEdge(dut.aclk)
    widths = []
    for _ in range(periods):
        high = [0] * 6
        while True:
            await RisingEdge(dut.aclk)
            if dut.servo_period_start.value == 1:
                break
            bits = int(dut.servo_pwm.value)
            for n in range(6):
                high[n] += bits >> n & 1
        widths.append(high)
    return widths


@cocotb.test()
async def servo_pwm_pulse_widths(dut):
    """Leg angles from the inverse kinematics' words set each channel's pulse to the model's
    width (0.5 to 2.5 ms over 0 to 180 degrees, a 250 kHz kernel clock) from the next period
    on; a pulse is never cut
    while a new angle arrives mid-period; an angle above 180 degrees is held at 2.5 ms with
    ``err_range``, a word for leg 7 is dropped with ``err_leg``; unset legs stay low."""
    from cocotbext.axi import AxiStreamBus, AxiStreamSource
    tb = ControlTB(dut)
    await tb.reset()
    errors = {"leg": 0, "range": 0}
    cocotb.start_soon(count_pulses(dut.servo_err_leg, errors, "leg"))
    cocotb.start_soon(count_pulses(dut.servo_err_range, errors, "range"))
    source = AxiStreamSource(AxiStreamBus.from_prefix(dut, "servo_i"), dut.aclk, dut.aresetn,
                             reset_active_level=False)
    source.set_pause_generator(random_pauses(tb.rng, 0.3))

    async def send(index, leg):
        await source.send(AxiStreamFrame(((index << 21) | (leg << 18)).to_bytes(4, "little")))
        await source.wait()

    assert (await pwm_pulses(dut, 1))[0] == [0] * 6, "a leg without an angle pulsed"
    angles = [0, 900, 1800, 450, 1234, 2047]          # the last one is above 180 degrees
    for leg, index in enumerate(angles[:5]):
        await send(index, leg)
    await send(333, 7)
    await send(angles[5], 5)
    first, second = await pwm_pulses(dut, 2)
    want = [servo_pulse(i, clock_hz=250_000) for i in angles]
    assert want[:3] == [125, 375, 625]
    assert first == want and second == want, (first, second, want)
    assert errors == {"leg": 1, "range": 1}, errors
    # a new angle for leg 0 300 cycles into a period: that pulse keeps its width, the next
    # one has the new width
    await RisingEdge(dut.aclk)
    while dut.servo_period_start.value != 1:
        await RisingEdge(dut.aclk)
    measure = cocotb.start_soon(pwm_pulses(dut, 2))     # from this period start on
    await ClockCycles(dut.aclk, 300)
    await send(1800, 0)
    during, after = await measure
    assert during == want and after == [625] + want[1:], (during, after)
