"""AVR221 discrete PID, written from docs/kernels.md (C semantics of the 16-bit AVR:
int16 error and D term wrap, C division truncates toward zero)."""

__all__ = ["AvrPid", "FirstOrderPlant", "wrap16"]

MAX_INT = 32767
MAX_LONG = (1 << 31) - 1
MAX_I_TERM = MAX_LONG // 2
SCALING = 128


def wrap16(x):
    return (x + 0x8000) % 0x10000 - 0x8000


def c_div(a, b):
    """C integer division (truncates toward zero)."""
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b >= 0) else -q


class AvrPid:
    """``pid_Init`` / ``pid_Controller`` / ``pid_Reset_Integrator`` of AVR221."""

    def __init__(self, p, i, d):
        self.p, self.i, self.d = p, i, d
        self.last_pv = 0
        self.sum = 0
        self.max_error = c_div(MAX_INT, p + 1)
        self.max_sum = c_div(MAX_I_TERM, i + 1)

    def reset_integrator(self):
        self.sum = 0

    def update(self, sp, pv):
        e = wrap16(sp - pv)
        if e > self.max_error:
            p_term = MAX_INT
        elif e < -self.max_error:
            p_term = -MAX_INT
        else:
            p_term = self.p * e
        t = self.sum + e
        if t > self.max_sum:
            i_term, self.sum = MAX_I_TERM, self.max_sum
        elif t < -self.max_sum:
            i_term, self.sum = -MAX_I_TERM, -self.max_sum
        else:
            self.sum = t
            i_term = self.i * self.sum
        d_term = wrap16(self.d * (self.last_pv - pv))
        self.last_pv = pv
        out = c_div(p_term + i_term + d_term, SCALING)
        return max(-MAX_INT, min(MAX_INT, out))


class FirstOrderPlant:
    """``y += (gain * u - y) >> shift`` (integer, floor): a first-order lag, the process the
    closed-loop test controls."""

    def __init__(self, gain_num=1, gain_den=4, shift=3):
        self.y = 0
        self.gain_num, self.gain_den, self.shift = gain_num, gain_den, shift

    def step(self, u):
        self.y += (u * self.gain_num // self.gain_den - self.y) >> self.shift
        return self.y
