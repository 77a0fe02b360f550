"""Integer MNIST CNN: 3 x (conv3x3 + ReLU + maxpool2), FC + ReLU, FC (docs/kernels.md)."""

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import data, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from ..params import ParameterError, check_choice
from ..stream import AXIStreamSignature
from .image import FrameGuard, image_stream_signature

__all__ = ["MnistCnn", "MNIST_RESULT"]

#: the result beat (176 bits, first member lowest)
MNIST_RESULT = data.StructLayout({"digit": 8, "reserved": 8,
                                  "scores": data.ArrayLayout(signed(16), 10)})

_CONVS = (("conv1", 1, 8, 28), ("conv2", 8, 16, 14), ("conv3", 16, 32, 7))
_FCS = (("fc1", 288, 64), ("fc2", 64, 10))


def _pack(values, bits):
    word = 0
    for n, v in enumerate(values):
        word |= (int(v) & ((1 << bits) - 1)) << (n * bits)
    return word


class MnistCnn(wiring.Component):
    """Classifies 28x28 ``mono8`` digits with the integer network of :mod:`gen.mnist`.

    Layers run one after the other, each with its own multipliers: a convolution takes one
    input channel of one output position per cycle (output channels x 9 multipliers), 2x2
    max-pooling on the fly, so conv1/2/3 take 784, 1568 and 576 cycles (conv3 computes only
    the 6x6 positions its floor pooling keeps); FC layers take one input per cycle (64 and 10
    multipliers): 288 and 64 cycles. With the image in (784 / P cycles) about 3,500 cycles
    per digit. Activations are block RAMs with a position per word (all channels) and nine
    read ports for the 3x3 window; the weights are ROMs with one input channel per word.

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
        shapes = {"conv1": (8, 1, 3, 3), "conv2": (16, 8, 3, 3), "conv3": (32, 16, 3, 3),
                  "fc1": (64, 288), "fc2": (10, 64)}
        for name, shape in shapes.items():
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

    def elaborate(self, platform):
        m = Module()
        P = self._p
        m.submodules.guard = guard = FrameGuard(1, P, 28, 28)
        wiring.connect(m, wiring.flipped(self.i), guard.i)
        m.d.comb += [guard.width.eq(28), guard.height.eq(28),
                     self.err_short.eq(guard.err_short), self.err_long.eq(guard.err_long)]

        # activation memories: the image, then each pooled conv output
        acts = [Memory(shape=8 * P, depth=784 // P, init=[])]
        for name, _, c_out, size in _CONVS:
            acts.append(Memory(shape=8 * c_out, depth=(size // 2) ** 2, init=[]))
        for n, mem in enumerate(acts):
            m.submodules[f"act{n}"] = mem

        # loading the image
        load_addr = Signal(range(784 // P + 1))
        start = [Signal(name=f"start_{n}") for n in range(len(_CONVS) + len(_FCS))]
        done = [Signal(name=f"done_{n}") for n in range(len(_CONVS) + len(_FCS))]
        busy = Signal()
        wr_img = acts[0].write_port()
        m.d.comb += [guard.o.tready.eq(~busy), wr_img.addr.eq(load_addr),
                     wr_img.data.eq(guard.o.tdata), wr_img.en.eq(guard.o.tvalid & ~busy)]
        with m.If(guard.o.tvalid & ~busy):
            m.d.sync += load_addr.eq(load_addr + 1)
            with m.If(guard.o.tlast):
                m.d.sync += [load_addr.eq(0), busy.eq(1)]
                m.d.comb += start[0].eq(1)

        for n, (name, c_in, c_out, size) in enumerate(_CONVS):
            self._conv(m, n, acts[n], acts[n + 1], c_in, c_out, size, start[n], done[n],
                       in_pixels_per_word=P if n == 0 else c_in)
            m.d.comb += start[n + 1].eq(done[n])

        fc_out = self._fcs(m, acts[-1], start[3], done[3], done[4])
        digit, scores = fc_out
        o_valid = Signal()
        m.d.comb += [self.o.tvalid.eq(o_valid), self.o.tlast.eq(1)]
        with m.If(self.o.tvalid & self.o.tready):
            m.d.sync += o_valid.eq(0)
        with m.If(done[4]):
            result = data.View(MNIST_RESULT, self.o.tdata)
            m.d.sync += [o_valid.eq(1), busy.eq(0), result.digit.eq(digit),
                         *[result.scores[k].eq(score) for k, score in enumerate(scores)]]
        # a new image is taken only once the result has left
        with m.If(o_valid & ~(self.o.tready)):
            m.d.comb += guard.o.tready.eq(0)
            m.d.comb += wr_img.en.eq(0)
        return m

    def _conv(self, m, n, src, dst, c_in, c_out, size, start, done, in_pixels_per_word):
        """One convolution layer with pooling (see the class docstring)."""
        w, b, shift = self._weights[f"conv{n + 1}"]
        pooled = size // 2
        # at least two entries: a one-entry ROM would have a zero-width address
        rom = Memory(shape=8 * 9 * c_out, depth=max(c_in, 2),
                     init=[_pack([w[o, c, dy, dx] for o in range(c_out) for dy in range(3)
                                  for dx in range(3)], 8) for c in range(c_in)])
        m.submodules[f"conv{n + 1}_w"] = rom
        w_rd = rom.read_port()
        ports = [src.read_port() for _ in range(9)]
        wr = dst.write_port()

        run = Signal(name=f"c{n}_run")
        py, px = Signal(range(pooled), name=f"c{n}_py"), Signal(range(pooled), name=f"c{n}_px")
        sub = Signal(2, name=f"c{n}_sub")
        c = Signal(range(max(c_in, 2)), name=f"c{n}_c")
        y = Cat(sub[1], py)
        x = Cat(sub[0], px)
        m.d.comb += w_rd.addr.eq(c)
        valid0 = []
        for t, port in enumerate(ports):
            dy, dx = t // 3 - 1, t % 3 - 1
            yy = Signal(signed(8), name=f"c{n}_y{t}")
            xx = Signal(signed(8), name=f"c{n}_x{t}")
            m.d.comb += [yy.eq(y + dy), xx.eq(x + dx)]
            pos = yy * size + xx
            if in_pixels_per_word == c_in:
                m.d.comb += port.addr.eq(pos)
            else:                      # the image: P pixels per word
                m.d.comb += port.addr.eq(pos >> (in_pixels_per_word.bit_length() - 1))
            valid0.append((yy >= 0) & (yy < size) & (xx >= 0) & (xx < size))
        # stage 1 registers: what the read data belong to
        v1 = Signal(name=f"c{n}_v1")
        ok1 = Signal(9, name=f"c{n}_ok1")
        sel1 = [Signal(range(max(c_in, in_pixels_per_word)), name=f"c{n}_sel1_{t}")
                for t in range(9)]
        first1, last1, sub1 = Signal(name=f"c{n}_first1"), Signal(name=f"c{n}_last1"), \
            Signal(2, name=f"c{n}_sub1")
        addr1 = Signal(range(pooled * pooled), name=f"c{n}_addr1")
        m.d.sync += [v1.eq(run), ok1.eq(Cat(*valid0)), first1.eq(c == 0),
                     last1.eq(c == c_in - 1), sub1.eq(sub), addr1.eq(py * pooled + px)]
        for t in range(9):
            if in_pixels_per_word == c_in:
                m.d.sync += sel1[t].eq(c)
            else:
                dx = t % 3 - 1
                m.d.sync += sel1[t].eq((x + dx)[:in_pixels_per_word.bit_length() - 1])
        with m.If(start):
            m.d.sync += [run.eq(1), py.eq(0), px.eq(0), sub.eq(0), c.eq(0)]
        with m.Elif(run):
            m.d.sync += c.eq(c + 1)
            with m.If(c == c_in - 1):
                m.d.sync += [c.eq(0), sub.eq(sub + 1)]
                with m.If(sub == 3):
                    m.d.sync += px.eq(px + 1)
                    with m.If(px == pooled - 1):
                        m.d.sync += [px.eq(0), py.eq(py + 1)]
                        with m.If(py == pooled - 1):
                            m.d.sync += run.eq(0)

        # stage 1: multiply-accumulate, requantize, pool, write
        acc = [Signal(signed(32), name=f"c{n}_acc{o}") for o in range(c_out)]
        best = [Signal(7, name=f"c{n}_max{o}") for o in range(c_out)]
        a = []
        for t, port in enumerate(ports):
            width = 8
            value = port.data.word_select(sel1[t], width)
            a.append(Mux(ok1[t], value, 0))
        results = []
        for o in range(c_out):
            products = [w_rd.data.word_select(o * 9 + t, 8).as_signed() * a[t]
                        for t in range(9)]
            total = Signal(signed(32), name=f"c{n}_sum{o}")
            m.d.comb += total.eq(Mux(first1, int(b[o]), acc[o]) + sum(products))
            q = Signal(signed(32), name=f"c{n}_q{o}")
            m.d.comb += q.eq(total >> int(shift))
            r = Signal(7, name=f"c{n}_r{o}")
            m.d.comb += r.eq(Mux(q < 0, 0, Mux(q > 127, 127, q)))
            pooled_r = Signal(7, name=f"c{n}_p{o}")
            m.d.comb += pooled_r.eq(Mux((sub1 == 0) | (r > best[o]), r, best[o]))
            results.append(pooled_r)
            with m.If(v1):
                m.d.sync += acc[o].eq(total)
                with m.If(last1):
                    m.d.sync += best[o].eq(pooled_r)
        m.d.comb += [wr.addr.eq(addr1), wr.data.eq(Cat(*[Cat(r, Const(0, 1)) for r in results])),
                     wr.en.eq(v1 & last1 & (sub1 == 3))]
        m.d.sync += done.eq(v1 & last1 & (sub1 == 3) & (addr1 == pooled * pooled - 1))

    def _fcs(self, m, src, start, done1, done2):
        """fc1 (ReLU, int8) and fc2 (int16 scores), one input per cycle; returns
        ``(digit, scores)`` valid when ``done2`` pulses."""
        w1, b1, s1 = self._weights["fc1"]
        w2, b2, s2 = self._weights["fc2"]
        rom1 = Memory(shape=8 * 64, depth=288,
                      init=[_pack(w1[:, i], 8) for i in range(288)])
        rom2 = Memory(shape=8 * 10, depth=64, init=[_pack(w2[:, j], 8) for j in range(64)])
        m.submodules.fc1_w, m.submodules.fc2_w = rom1, rom2
        r1, r2 = rom1.read_port(), rom2.read_port()
        port = src.read_port()

        # fc1: input i = channel i // 9 at position i % 9 (channel-major flatten)
        run1, i = Signal(), Signal(range(288))
        ch, pos = Signal(range(32)), Signal(range(9))
        m.d.comb += [r1.addr.eq(i), port.addr.eq(pos)]
        v1, ch1, last1 = Signal(), Signal(range(32)), Signal()
        m.d.sync += [v1.eq(run1), ch1.eq(ch), last1.eq(i == 287)]
        with m.If(start):
            m.d.sync += [run1.eq(1), i.eq(0), ch.eq(0), pos.eq(0)]
        with m.Elif(run1):
            m.d.sync += [i.eq(i + 1), pos.eq(pos + 1)]
            with m.If(pos == 8):
                m.d.sync += [pos.eq(0), ch.eq(ch + 1)]
            with m.If(i == 287):
                m.d.sync += run1.eq(0)
        a = port.data.word_select(ch1, 8)
        acc1 = [Signal(signed(32), name=f"fc1_acc{o}") for o in range(64)]
        hidden = [Signal(7, name=f"fc1_h{o}") for o in range(64)]
        first = Signal()
        m.d.sync += first.eq(i == 0)
        for o in range(64):
            total = Mux(first, int(b1[o]), acc1[o]) + r1.data.word_select(o, 8).as_signed() * a
            tsig = Signal(signed(32), name=f"fc1_sum{o}")
            m.d.comb += tsig.eq(total)
            q = tsig >> int(s1)
            with m.If(v1):
                m.d.sync += acc1[o].eq(tsig)
                with m.If(last1):
                    m.d.sync += hidden[o].eq(Mux(q < 0, 0, Mux(q > 127, 127, q)))
        m.d.sync += done1.eq(v1 & last1)

        # fc2
        run2, j = Signal(), Signal(range(64))
        m.d.comb += r2.addr.eq(j)
        v2, j1, last2 = Signal(), Signal(range(64)), Signal()
        m.d.sync += [v2.eq(run2), j1.eq(j), last2.eq(j == 63)]
        with m.If(done1):
            m.d.sync += [run2.eq(1), j.eq(0)]
        with m.Elif(run2):
            m.d.sync += j.eq(j + 1)
            with m.If(j == 63):
                m.d.sync += run2.eq(0)
        h = Signal(7)
        with m.Switch(j1):
            for k in range(64):
                with m.Case(k):
                    m.d.comb += h.eq(hidden[k])
        first2 = Signal()
        m.d.sync += first2.eq(j == 0)
        acc2 = [Signal(signed(32), name=f"fc2_acc{k}") for k in range(10)]
        scores = [Signal(signed(16), name=f"score{k}") for k in range(10)]
        for k in range(10):
            tsig = Signal(signed(32), name=f"fc2_sum{k}")
            m.d.comb += tsig.eq(Mux(first2, int(b2[k]), acc2[k]) +
                                r2.data.word_select(k, 8).as_signed() * h)
            q = Signal(signed(32), name=f"fc2_q{k}")
            m.d.comb += q.eq(tsig >> int(s2))
            with m.If(v2):
                m.d.sync += acc2[k].eq(tsig)
                with m.If(last2):
                    m.d.sync += scores[k].eq(Mux(q < -32768, -32768, Mux(q > 32767, 32767, q)))
        done2_r = Signal()
        m.d.sync += done2_r.eq(v2 & last2)
        m.d.comb += done2.eq(done2_r)
        digit = Signal(4)
        best = scores[0]
        idx = Const(0, 4)
        for k in range(1, 10):
            better = Signal(name=f"better{k}")
            m.d.comb += better.eq(scores[k] > best)
            nb = Signal(signed(16), name=f"best{k}")
            ni = Signal(4, name=f"bidx{k}")
            m.d.comb += [nb.eq(Mux(better, scores[k], best)), ni.eq(Mux(better, k, idx))]
            best, idx = nb, ni
        m.d.comb += digit.eq(idx)
        return digit, scores
