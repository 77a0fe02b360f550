"""Lane following and lane control of the AutoRace chain (docs/kernels.md, docs/av_chain.md):
the lane centre from the stripes' colours in a bird's-eye view, and the driving command."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..params import check_int
from ..stream import AXIStreamSignature
from .colour import TRAFFIC_DETECTION, BgrToHsv, in_range
from .image import image_stream_signature

__all__ = ["LaneDetector", "LaneControl", "LightEvent", "LightNode", "LANE_RESULT",
           "DRIVE_COMMAND", "EVENT_STREAM"]

#: a stream of one-beat messages: lane results, light events, driving commands
EVENT_STREAM = AXIStreamSignature(64, keep=False)

#: one per frame: the means of the two stripes and the centre (bird's-eye columns)
LANE_RESULT = data.StructLayout({"centre": signed(16), "left": 16, "right": 16,
                                 "has_centre": 1, "has_left": 1, "has_right": 1, "pad": 13})
#: the driving command: speed in mm/s, turn rate in mrad/s (positive: left)
DRIVE_COMMAND = data.StructLayout({"speed": signed(16), "turn": signed(16), "stopped": 1,
                                   "pad": 31})


class LaneDetector(wiring.Component):
    """The lane centre in a ``bgr8`` bird's-eye view (host.autorace.lane_centre).

    Every pixel of rows ``band_top`` to the bottom is converted to HSV (``BgrToHsv``) and
    tested against the yellow (left stripe) and white (right stripe) ranges (``cv2.inRange``);
    the kernel counts each colour's pixels ``N`` and sums their columns ``S``. At the end of
    the frame, with a colour that has fewer than ``min_pixels`` counted as missing: ``left =
    Sy // Ny``, ``right = Sw // Nw``, the centre ``(2 Sy Nw + 2 Sw Ny + 2 Ny Nw) // (4 Ny
    Nw)`` (the mean of the two means, rounded half up), or with one stripe only its mean +-
    ``lane_width / 2`` rounded half up; no centre without either. One :data:`LANE_RESULT` beat
    per frame, about 60 cycles after the frame's last beat (the divisions).

    Parameters
    ----------
    width, height : int
        The bird's-eye frame (AutoRace: 1000 x 600).
    band_top, lane_width, min_pixels : int
        ``lane_width`` even.
    yellow, white : ((H, S, V), (H, S, V))
        Inclusive HSV bounds.
    pixels_per_beat : int

    Members
    -------
    i : In(image_stream_signature(3, pixels_per_beat))
    o : Out(AXIStreamSignature(64, keep=False))
        One :data:`LANE_RESULT` per frame, ``tlast`` set.
    err_short, err_long, err_size : Out(1)
        Bad frames (:class:`~hdl.kernels.image.FrameGuard`): a padded or cut frame still gives
        a result.
    """

    def __init__(self, *, width=1000, height=600, band_top=400, lane_width=300,
                 min_pixels=200, yellow=((20, 100, 100), (40, 255, 255)),
                 white=((0, 0, 170), (179, 60, 255)), pixels_per_beat=1):
        check_int("width", width, pixels_per_beat, 4095)
        check_int("height", height, 1, 4095)
        check_int("band_top", band_top, 0, height - 1)
        check_int("lane_width", lane_width, 0, 4094, multiple_of=2)
        check_int("min_pixels", min_pixels, 1, width * height)
        self._size = (width, height)
        self._band_top, self._lane_width, self._min = band_top, lane_width, min_pixels
        self._yellow = tuple(tuple(b) for b in yellow)
        self._white = tuple(tuple(b) for b in white)
        self._p = pixels_per_beat
        super().__init__({"i": In(image_stream_signature(3, pixels_per_beat)),
                          "o": Out(AXIStreamSignature(64, keep=False)),
                          "err_short": Out(1), "err_long": Out(1), "err_size": Out(1)})

    def elaborate(self, platform):
        m = Module()
        P = self._p
        W, H = self._size
        m.submodules.hsv = hsv = BgrToHsv(pixels_per_beat=P, max_width=W, max_height=H)
        wiring.connect(m, wiring.flipped(self.i), hsv.i)
        m.d.comb += [hsv.width.eq(W), hsv.height.eq(H), self.err_short.eq(hsv.err_short),
                     self.err_long.eq(hsv.err_long), self.err_size.eq(hsv.err_size)]

        row, col = Signal(range(H + 1)), Signal(range(W + 1))
        count_bits = (W * H).bit_length()
        sum_bits = (W * W * H).bit_length()
        ny, nw = Signal(count_bits), Signal(count_bits)
        sy, sw = Signal(sum_bits), Signal(sum_bits)
        # a beat's stripe flags are registered before they are counted and summed, so the
        # HSV range checks and the adder tree take a cycle each
        yellow, white = Signal(P), Signal(P)
        beat_col, beat_valid, beat_last = Signal.like(col), Signal(), Signal()
        in_band = row >= self._band_top
        add_ny, add_nw = Const(0, count_bits), Const(0, count_bits)
        add_sy, add_sw = Const(0, sum_bits), Const(0, sum_bits)
        for p in range(P):
            px = hsv.o.tdata.word_select(p, 24)
            m.d.sync += [yellow[p].eq(in_band & in_range(px, self._yellow[0], self._yellow[1])),
                         white[p].eq(in_band & in_range(px, self._white[0], self._white[1]))]
            add_ny = add_ny + yellow[p]
            add_nw = add_nw + white[p]
            add_sy = add_sy + Mux(yellow[p], beat_col + p, 0)
            add_sw = add_sw + Mux(white[p], beat_col + p, 0)

        busy = Signal()
        take = hsv.o.tvalid & hsv.o.tready
        m.d.comb += hsv.o.tready.eq(~busy & ~(beat_valid & beat_last))
        m.d.sync += [beat_valid.eq(take), beat_col.eq(col), beat_last.eq(hsv.o.tlast)]
        with m.If(take):
            with m.If(hsv.o.tlast):
                m.d.sync += [row.eq(0), col.eq(0)]
            with m.Elif(col + P == W):
                m.d.sync += [col.eq(0), row.eq(row + 1)]
            with m.Else():
                m.d.sync += col.eq(col + P)
        # the frame's totals, then the divisions
        ty, tw, tsy, tsw = (Signal(count_bits), Signal(count_bits), Signal(sum_bits),
                            Signal(sum_bits))
        has_y, has_w = Signal(), Signal()
        with m.If(beat_valid):
            with m.If(beat_last):
                m.d.sync += [ty.eq(ny + add_ny), tw.eq(nw + add_nw), tsy.eq(sy + add_sy),
                             tsw.eq(sw + add_sw), ny.eq(0), nw.eq(0), sy.eq(0), sw.eq(0),
                             has_y.eq(ny + add_ny >= self._min),
                             has_w.eq(nw + add_nw >= self._min), busy.eq(1)]
            with m.Else():
                m.d.sync += [ny.eq(ny + add_ny), nw.eq(nw + add_nw), sy.eq(sy + add_sy),
                             sw.eq(sw + add_sw)]

        # a serial divider: quotient = numer // divisor, 16 quotient bits (the results are
        # columns below 4096 and halves of them)
        qbits = 16
        nbits = 2 * sum_bits + 4
        numer, shifted = Signal(nbits), Signal(nbits + qbits)
        quotient = Signal(qbits)
        k = Signal(range(qbits + 1))
        result = Signal(LANE_RESULT)
        out_valid = Signal()
        m.d.comb += [self.o.tvalid.eq(out_valid), self.o.tdata.eq(result), self.o.tlast.eq(1)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += out_valid.eq(0)

        def start(n, d, then, steps=qbits):
            # the divisor shifted into place once, then one bit right per step (no barrel
            # shifter between the step count and the comparison)
            m.d.sync += [numer.eq(n), shifted.eq(d << (steps - 1)), quotient.eq(0),
                         k.eq(steps)]
            m.next = then

        def divide(done):
            ge = numer >= shifted
            m.d.sync += [numer.eq(Mux(ge, numer - shifted, numer)), shifted.eq(shifted >> 1),
                         quotient.eq(Cat(ge, quotient[:-1])), k.eq(k - 1)]
            with m.If(k == 1):
                done(Cat(ge, quotient[:-1]))

        half = self._lane_width
        # the centre's products Sy Nw, Sw Ny, Ny Nw, each split into partial products
        pairs = ((tsy, tw), (tsw, ty), (ty, tw))
        splits = [_partial_products(a, b) for a, b in pairs]
        partials = [[Signal(len(x) + len(y)) for x, y, _ in split] for split in splits]
        products = [Signal(len(a) + len(b)) for a, b in pairs]
        y_only = Signal(count_bits + 12)
        with m.FSM():
            with m.State("COUNT"):
                with m.If(busy & ~out_valid):
                    m.d.sync += result.eq(0)
                    with m.If(has_y):
                        start(tsy, ty, "DIV_LEFT")
                    with m.Else():
                        m.next = "RIGHT"
            with m.State("DIV_LEFT"):
                def left_done(q):
                    m.d.sync += [result.left.eq(q), result.has_left.eq(1)]
                    m.next = "RIGHT"
                divide(left_done)
            with m.State("RIGHT"):
                with m.If(has_w):
                    start(tsw, tw, "DIV_RIGHT")
                with m.Else():
                    m.next = "CENTRE"
            with m.State("DIV_RIGHT"):
                def right_done(q):
                    m.d.sync += [result.right.eq(q), result.has_right.eq(1)]
                    m.next = "CENTRE"
                divide(right_done)
            with m.State("CENTRE"):
                # the products as partial products of at most 18x18 bits (one multiplier
                # each), registered, then summed, then the numerator; the centre's quotient
                # is below 2**13, so its division takes two steps less and the frame no
                # cycle more
                for parts, split in zip(partials, splits):
                    for reg, (x, y, _) in zip(parts, split):
                        m.d.sync += reg.eq(x * y)
                m.d.sync += y_only.eq(ty * (half + 1))
                with m.If(has_y | has_w):
                    m.next = "CENTRE_ADD"
                with m.Else():
                    m.next = "SEND"
            with m.State("CENTRE_ADD"):
                for product, parts, split in zip(products, partials, splits):
                    m.d.sync += product.eq(sum(reg << shift
                                               for reg, (_, _, shift) in zip(parts, split)))
                m.next = "CENTRE_SUM"
            with m.State("CENTRE_SUM"):
                sy_nw, sw_ny, ny_nw = products
                with m.If(has_y & has_w):
                    start(2 * (sy_nw + sw_ny + ny_nw), 4 * ny_nw, "DIV_CENTRE", qbits - 2)
                with m.Elif(has_y):
                    start(2 * tsy + y_only, 2 * ty, "DIV_CENTRE", qbits - 2)
                with m.Else():
                    # (2 Sw - Nw lane_width + Nw) // (2 Nw); the numerator may be negative
                    start(2 * tsw + tw, 2 * tw, "DIV_ONE_SIDED", qbits - 2)
            with m.State("DIV_CENTRE"):
                def centre_done(q):
                    m.d.sync += [result.centre.eq(q), result.has_centre.eq(1)]
                    m.next = "SEND"
                divide(centre_done)
            with m.State("DIV_ONE_SIDED"):
                def one_sided_done(q):
                    # floor((2 Sw - Nw lane_width + Nw) / (2 Nw)) = floor((2 Sw + Nw) /
                    # (2 Nw)) - lane_width / 2 (lane_width is even)
                    m.d.sync += [result.centre.eq(q - (half >> 1)),
                                 result.has_centre.eq(1)]
                    m.next = "SEND"
                divide(one_sided_done)
            with m.State("SEND"):
                m.d.sync += [out_valid.eq(1), busy.eq(0)]
                m.next = "COUNT"
        return m


def _partial_products(a, b, bits=17):
    """``(x, y, shift)`` with ``a * b == sum(x * y << shift)``, each ``x`` and ``y`` at most
    ``bits`` wide (an unsigned operand of one ECP5 or Xilinx multiplier)."""
    def pieces(v):
        return [(v[i:i + bits], i) for i in range(0, len(v), bits)]
    return [(x, y, i + j) for x, i in pieces(a) for y, j in pieces(b)]


class LaneControl(wiring.Component):
    """AutoRace's ``control_lane`` in integers (host.autorace.LaneControl): from each lane
    result the error ``centre - target``, the turn rate ``-(kp e + kd (e - last e)) / 1024``
    mrad/s (toward zero, limited to ``max_turn``) and the speed ``max_speed (500 - |e|) // 500``
    mm/s (0 beyond); a result without a centre repeats the last command. A stop event holds
    the command at 0 until a start event. One :data:`DRIVE_COMMAND` per lane result, 20
    cycles later (a 15-step division by 500).

    Parameters
    ----------
    kp, kd : int
        Gains in 1/1024 mrad/s per pixel, 0..65535.
    max_speed, max_turn, target : int

    Members
    -------
    lane : In(AXIStreamSignature(64, keep=False))
        :data:`LANE_RESULT` beats.
    stop, start : In(stream.Signature(1))
        Events (their payload is ignored); a stop and a start in the same cycle: start wins.
    o : Out(AXIStreamSignature(64, keep=False))
        :data:`DRIVE_COMMAND` beats, ``tlast`` set.
    """

    def __init__(self, *, kp=2560, kd=7168, max_speed=220, max_turn=2000, target=500):
        self._kp = check_int("kp", kp, 0, 65535)
        self._kd = check_int("kd", kd, 0, 65535)
        self._max_speed = check_int("max_speed", max_speed, 0, 32767)
        self._max_turn = check_int("max_turn", max_turn, 0, 32767)
        self._target = check_int("target", target, 0, 4095)
        super().__init__({"lane": In(AXIStreamSignature(64, keep=False)),
                          "stop": In(stream.Signature(1)), "start": In(stream.Signature(1)),
                          "o": Out(AXIStreamSignature(64, keep=False))})

    def elaborate(self, platform):
        m = Module()
        stopped = Signal()
        m.d.comb += [self.stop.ready.eq(1), self.start.ready.eq(1)]
        with m.If(self.start.valid):
            m.d.sync += stopped.eq(0)
        with m.Elif(self.stop.valid):
            m.d.sync += stopped.eq(1)

        lane = data.View(LANE_RESULT, self.lane.tdata)
        last_error = Signal(signed(17))
        speed, turn = Signal(signed(16)), Signal(signed(16))
        error = Signal(signed(17))
        raw = Signal(signed(40))
        numer, quotient, k = Signal(30), Signal(16), Signal(range(17))
        abs_error, magnitude, turn_left = Signal(17), Signal(30), Signal()
        out_valid = Signal()
        cmd = Signal(DRIVE_COMMAND)
        m.d.comb += [self.o.tvalid.eq(out_valid), self.o.tdata.eq(cmd), self.o.tlast.eq(1)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += out_valid.eq(0)
        with m.FSM():
            with m.State("WAIT"):
                m.d.comb += self.lane.tready.eq(~out_valid)
                with m.If(self.lane.tvalid & ~out_valid):
                    with m.If(lane.has_centre):
                        e = lane.centre - self._target
                        m.d.sync += [error.eq(e),
                                     raw.eq(self._kp * e + self._kd * (e - last_error)),
                                     last_error.eq(e)]
                        m.next = "TURN"
                    with m.Else():
                        m.next = "SEND"
            with m.State("TURN"):
                m.d.sync += [abs_error.eq(Mux(error < 0, -error, error)),
                             magnitude.eq(Mux(raw < 0, -raw, raw) >> 10), turn_left.eq(raw > 0)]
                m.next = "NUMERATOR"
            with m.State("NUMERATOR"):
                # registered |e| and |raw| keep each of these cycles to one carry chain deep
                limited = Mux(magnitude > self._max_turn, self._max_turn, magnitude)
                m.d.sync += [turn.eq(Mux(turn_left, -limited, limited)),
                             numer.eq(Mux(abs_error >= 500, 0,
                                          self._max_speed * (500 - abs_error))),
                             quotient.eq(0), k.eq(15)]
                m.next = "SPEED"
            with m.State("SPEED"):
                # (max_speed (500 - |e|)) // 500, one quotient bit per cycle; it is below
                # 2**15 (max_speed < 2**15), so 15 steps
                shifted = Const(500, 30) << (k - 1).as_unsigned()
                ge = numer >= shifted
                m.d.sync += [numer.eq(Mux(ge, numer - shifted, numer)),
                             quotient.eq(Cat(ge, quotient[:-1])), k.eq(k - 1)]
                with m.If(k == 1):
                    m.d.sync += speed.eq(Cat(ge, quotient[:-1]))
                    m.next = "SEND"
            with m.State("SEND"):
                m.d.sync += [out_valid.eq(1), cmd.stopped.eq(stopped),
                             cmd.speed.eq(Mux(stopped, 0, speed)),
                             cmd.turn.eq(Mux(stopped, 0, turn))]
                m.next = "WAIT"
        return m


class LightEvent(wiring.Component):
    """Turns a traffic-light detector's beat per frame into events: ``colour`` ``"red"``
    sends a stop event on every frame with red; ``"green"`` sends a start event on a frame
    with green once armed by a stop event (``arm``), and disarms.

    Parameters
    ----------
    colour : str
        ``"red"`` or ``"green"``.
    every_frame : bool
        Emit a beat for every frame, ``tuser`` set on those that are events (for a node that
        must know a frame is done, such as a ReconOS thread); otherwise only the events.

    Members
    -------
    det : In(EVENT_STREAM)
        :data:`~hdl.kernels.colour.TRAFFIC_DETECTION` beats.
    arm : In(stream.Signature(1))
        Stop events (green only; always ready).
    event : Out(EVENT_STREAM)
        One beat per event (or per frame), ``tdata`` the frame's number from 0, ``tlast`` set.
    """

    COLOURS = ("red", "green")

    def __init__(self, colour, *, every_frame=False):
        from ..params import check_choice
        self.colour = check_choice("colour", colour, self.COLOURS)
        self.every_frame = bool(every_frame)
        out = AXIStreamSignature(64, keep=False, user_width=1) if every_frame else EVENT_STREAM
        super().__init__({"det": In(EVENT_STREAM), "arm": In(stream.Signature(1)),
                          "event": Out(out)})

    def elaborate(self, platform):
        m = Module()
        det = data.View(TRAFFIC_DETECTION, self.det.tdata)
        frame = Signal(32)
        armed = Signal()
        seen = det.red if self.colour == "red" else (det.green & armed)
        pending = Signal()
        m.d.comb += [self.arm.ready.eq(1), self.event.tvalid.eq(pending),
                     self.event.tlast.eq(1), self.det.tready.eq(~pending)]
        with m.If(self.arm.valid):
            m.d.sync += armed.eq(1)
        with m.If(self.event.tvalid & self.event.tready):
            m.d.sync += pending.eq(0)
        with m.If(self.det.tvalid & self.det.tready):
            m.d.sync += frame.eq(frame + 1)
            if self.every_frame:
                m.d.sync += [pending.eq(1), self.event.tdata.eq(frame),
                             self.event.tuser.eq(seen)]
            else:
                with m.If(seen):
                    m.d.sync += [pending.eq(1), self.event.tdata.eq(frame)]
            with m.If(seen):
                if self.colour == "green":
                    m.d.sync += armed.eq(0)
        return m


class LightNode(wiring.Component):
    """A traffic-light node as one kernel: a :class:`~hdl.kernels.TrafficLightDetector` and a
    :class:`LightEvent` that reports every frame (for a ReconOS thread, which publishes the
    frames that are events).

    Parameters
    ----------
    colour : str
        ``"red"`` (stop events) or ``"green"`` (start events once armed).
    **detector :
        The :class:`~hdl.kernels.TrafficLightDetector` parameters.

    Members
    -------
    i, width, height, err_short, err_long, err_size :
        As the detector's.
    arm : In(stream.Signature(1))
        As :class:`LightEvent`'s.
    o : Out(AXIStreamSignature(64, keep=False, user_width=1))
        One beat per frame: ``tdata`` the frame's number, ``tuser`` set on an event.
    """

    def __init__(self, colour, **detector):
        from .colour import TrafficLightDetector
        self.detector = TrafficLightDetector(**detector)
        self.events = LightEvent(colour, every_frame=True)
        members = {k: v for k, v in self.detector.signature.members.items() if k != "det"}
        super().__init__({**members, "arm": In(stream.Signature(1)),
                          "o": Out(self.events.signature.members["event"].signature)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.detector = det = self.detector
        m.submodules.events = ev = self.events
        for name, member in self.signature.members.items():
            if name in ("arm", "o"):
                continue
            if member.is_signature:
                wiring.connect(m, wiring.flipped(getattr(self, name)), getattr(det, name))
            elif member.flow == In:
                m.d.comb += getattr(det, name).eq(getattr(self, name))
            else:
                m.d.comb += getattr(self, name).eq(getattr(det, name))
        wiring.connect(m, det.det, ev.det)
        wiring.connect(m, wiring.flipped(self.arm), ev.arm)
        wiring.connect(m, ev.event, wiring.flipped(self.o))
        return m
