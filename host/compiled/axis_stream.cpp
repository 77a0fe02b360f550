// The packet FIFOs of rosgate_axis_source and rosgate_axis_sink (axis_stream.sv): the
// simulated ports step through them at each clock edge (DPI-C); Python puts packets into a
// source and takes packets out of a sink through ctypes (host/compiled/streams.py), in the
// same process as the Verilator model. A port is found by its name from either side.
#include <cstdint>
#include <cstring>
#include <deque>
#include <string>
#include <vector>

#include "svdpi.h"

#define ROSGATE_EXPORT extern "C" __attribute__((visibility("default"), used))

namespace {

struct Packet {
    std::vector<uint8_t> data;  // source: the bytes; sink: every lane of every beat
    std::vector<uint8_t> keep;  // sink: tkeep of every lane
    std::vector<uint64_t> user; // source: one value for every beat; sink: tuser per beat
};

enum Pause { NONE = 0, RANDOM = 1 };

struct Port {
    std::string name;
    int sink = 0;
    int data_w = 0, user_w = 0, has_keep = 1;
    // source: packets waiting, the one on its way and where in it
    std::deque<Packet> queue;
    Packet current;
    bool active = false;
    size_t offset = 0;
    bool on_bus = false;  // a beat is presented (tvalid high after the last edge)
    bool withdraw = false;  // take the beat off the bus at the next edge, taken or not
    // sink: packets complete, the one arriving
    std::deque<Packet> done;
    Packet partial;
    // pauses: ``forced`` pauses every cycle; RANDOM draws runs of pausing or not
    bool forced = false;
    int mode = NONE;
    uint32_t threshold = 0;
    uint32_t max_run = 1;
    uint64_t state = 1;
    uint32_t run_left = 0;
    bool run_value = false;
    // counters since the port was opened
    uint64_t cycles = 0, beats = 0, packets = 0, stalls = 0;
    bool record = false;
    std::vector<uint64_t> transfers;  // the cycle of every beat, while ``record``
};

std::vector<Port> ports;

uint64_t next_random(Port& p) {
    // xorshift64*: a seeded sequence per port, independent of the other ports' traffic
    p.state ^= p.state >> 12;
    p.state ^= p.state << 25;
    p.state ^= p.state >> 27;
    return p.state * 0x2545F4914F6CDD1DULL;
}

bool paused(Port& p) {
    bool value = false;
    if (p.mode == RANDOM) {
        if (p.run_left == 0) {
            p.run_value = static_cast<uint32_t>(next_random(p) >> 32) < p.threshold;
            p.run_left = p.max_run <= 1 ? 1 : 1 + static_cast<uint32_t>(next_random(p) >> 33) % p.max_run;
        }
        p.run_left--;
        value = p.run_value;
    }
    return value || p.forced;
}

Port* find(int port) {
    if (port < 0 || static_cast<size_t>(port) >= ports.size()) return nullptr;
    return &ports[port];
}

void note_beat(Port& p) {
    p.beats++;
    if (p.record) p.transfers.push_back(p.cycles);
}

}  // namespace

// Both sides: the port called ``name`` (opened on first use). The simulated port gives its
// direction and widths; Python passes a negative ``data_w`` and learns them later.
ROSGATE_EXPORT int rosgate_axis_open(const char* name, int sink, int data_w, int user_w,
                                     int has_keep) {
    int id = -1;
    for (size_t i = 0; i < ports.size(); i++)
        if (ports[i].name == name) id = static_cast<int>(i);
    if (id < 0) {
        ports.emplace_back();
        ports.back().name = name;
        ports.back().data_w = -1;
        id = static_cast<int>(ports.size() - 1);
    }
    if (data_w >= 0) {
        Port& p = ports[id];
        p.sink = sink;
        p.data_w = data_w;
        p.user_w = user_w;
        p.has_keep = has_keep;
    }
    return id;
}

// Python: direction (0 source, 1 sink), data width, tuser width, whether tkeep is wired;
// a data width of -1 means the simulated port has not opened it (yet).
ROSGATE_EXPORT int rosgate_axis_shape(int port, int what) {
    Port* p = find(port);
    if (!p) return -2;
    switch (what) {
        case 0: return p->sink;
        case 1: return p->data_w;
        case 2: return p->user_w;
        default: return p->has_keep;
    }
}

// Python: a packet of ``n`` bytes for a source, ``user`` on each of its beats.
ROSGATE_EXPORT int rosgate_axis_send(int port, const uint8_t* data, uint64_t n, uint64_t user) {
    Port* p = find(port);
    if (!p || n == 0) return -1;
    Packet packet;
    packet.data.assign(data, data + n);
    packet.user.push_back(user);
    p->queue.push_back(std::move(packet));
    return 0;
}

// Python: packets a source has not finished presenting, and whether its last beat is still
// on the bus (0: the source is idle).
ROSGATE_EXPORT uint64_t rosgate_axis_waiting(int port) {
    Port* p = find(port);
    if (!p) return 0;
    return p->queue.size() + (p->active ? 1 : 0) + (!p->active && p->on_bus ? 1 : 0);
}

ROSGATE_EXPORT uint64_t rosgate_axis_queued(int port) {
    Port* p = find(port);
    return p ? p->queue.size() : 0;
}

// Python: a new driver on the port (a new test): nothing queued, nothing on its way (a beat on
// the bus is withdrawn at the next edge), no pauses, counters at zero, as a new cocotbext-axi
// source or sink starts.
ROSGATE_EXPORT void rosgate_axis_restart(int port) {
    Port* p = find(port);
    if (!p) return;
    const std::string name = p->name;
    const int sink = p->sink, data_w = p->data_w, user_w = p->user_w, has_keep = p->has_keep;
    const bool withdraw = p->on_bus;
    const uint64_t cycles = p->cycles;
    *p = Port();
    p->name = name;
    p->sink = sink;
    p->data_w = data_w;
    p->user_w = user_w;
    p->has_keep = has_keep;
    p->withdraw = withdraw;
    p->cycles = cycles;
}

// Python: forget the packets a source has not begun, or a sink's complete packets.
ROSGATE_EXPORT void rosgate_axis_clear(int port) {
    Port* p = find(port);
    if (!p) return;
    p->queue.clear();
    p->done.clear();
}

// Python: pause every cycle (``forced``), and random runs: each run pauses with probability
// ``threshold`` / 2^32 and lasts 1..max_run cycles, drawn from ``seed``.
ROSGATE_EXPORT void rosgate_axis_pause(int port, int forced, int random, uint32_t threshold,
                                       uint32_t max_run, uint64_t seed) {
    Port* p = find(port);
    if (!p) return;
    p->forced = forced != 0;
    p->mode = random ? RANDOM : NONE;
    p->threshold = threshold;
    p->max_run = max_run ? max_run : 1;
    p->state = seed ? seed : 0x9E3779B97F4A7C15ULL;
    p->run_left = 0;
}

ROSGATE_EXPORT void rosgate_axis_force_pause(int port, int forced) {
    Port* p = find(port);
    if (p) p->forced = forced != 0;
}

// Python: counters: 0 clock edges, 1 beats, 2 packets, 3 cycles with tvalid and no tready.
ROSGATE_EXPORT uint64_t rosgate_axis_counter(int port, int which) {
    Port* p = find(port);
    if (!p) return 0;
    const uint64_t values[] = {p->cycles, p->beats, p->packets, p->stalls};
    return which >= 0 && which < 4 ? values[which] : 0;
}

ROSGATE_EXPORT void rosgate_axis_reset_counters(int port) {
    Port* p = find(port);
    if (!p) return;
    p->beats = p->packets = p->stalls = 0;
    p->transfers.clear();
}

// Python: record the cycle (counter 0) of every beat from now on, or stop.
ROSGATE_EXPORT void rosgate_axis_record(int port, int on) {
    Port* p = find(port);
    if (p) p->record = on != 0;
}

ROSGATE_EXPORT uint64_t rosgate_axis_transfers(int port, uint64_t* out, uint64_t capacity) {
    Port* p = find(port);
    if (!p) return 0;
    const uint64_t n = p->transfers.size();
    if (out) std::memcpy(out, p->transfers.data(), 8 * (n < capacity ? n : capacity));
    return n;
}

// Python: lanes (bytes) and beats of a sink's oldest complete packet; -1 when none.
ROSGATE_EXPORT int64_t rosgate_axis_next(int port, uint64_t* beats) {
    Port* p = find(port);
    if (!p || p->done.empty()) return -1;
    *beats = p->done.front().user.size();
    return static_cast<int64_t>(p->done.front().data.size());
}

// Python: take that packet: its lanes, tkeep per lane and tuser per beat.
ROSGATE_EXPORT int rosgate_axis_take(int port, uint8_t* data, uint8_t* keep, uint64_t* user) {
    Port* p = find(port);
    if (!p || p->done.empty()) return -1;
    const Packet& packet = p->done.front();
    std::memcpy(data, packet.data.data(), packet.data.size());
    std::memcpy(keep, packet.keep.data(), packet.keep.size());
    std::memcpy(user, packet.user.data(), 8 * packet.user.size());
    p->done.pop_front();
    return 0;
}

ROSGATE_EXPORT uint64_t rosgate_axis_complete(int port) {
    Port* p = find(port);
    return p ? p->done.size() : 0;
}

// DPI (rosgate_axis_source): one clock edge; see axis_stream.sv for the bits returned.
ROSGATE_EXPORT int rosgate_axis_source_step(int port, int resetn, int valid, int ready,
                                            int last, svBitVecVal* data, svBitVecVal* keep,
                                            svBitVecVal* user) {
    Port* p = find(port);
    if (!p) return 0;
    p->cycles++;
    const bool pause = paused(*p);
    const int lanes = p->data_w / 8;
    std::memset(data, 0, 128);
    std::memset(keep, 0, 16);
    std::memset(user, 0, 8);
    if (!resetn) {
        p->active = false;
        p->on_bus = false;
        return 1;
    }
    int result = 0;
    if (valid && ready) {
        note_beat(*p);
        if (last) {
            p->packets++;
            result |= 8;
        }
    } else if (valid) {
        p->stalls++;
    }
    if (!(valid && ready) && valid && !p->withdraw) return result;  // the beat stays
    p->withdraw = false;
    if (!p->active && !p->queue.empty()) {
        p->current = std::move(p->queue.front());
        p->queue.pop_front();
        p->active = true;
        p->offset = 0;
    }
    result |= 1;
    p->on_bus = false;
    if (!p->active || pause) return result;
    const size_t n = p->current.data.size();
    for (int lane = 0; lane < lanes && p->offset < n; lane++, p->offset++) {
        data[lane / 4] |= static_cast<svBitVecVal>(p->current.data[p->offset]) << (8 * (lane % 4));
        keep[lane / 32] |= 1u << (lane % 32);
    }
    const uint64_t u = p->current.user.empty() ? 0 : p->current.user[0];
    user[0] = static_cast<svBitVecVal>(u);
    user[1] = static_cast<svBitVecVal>(u >> 32);
    result |= 2;
    p->on_bus = true;
    if (p->offset >= n) {
        result |= 4;
        p->active = false;
    }
    return result;
}

// DPI (rosgate_axis_sink): one clock edge; see axis_stream.sv for the bits returned.
ROSGATE_EXPORT int rosgate_axis_sink_step(int port, int resetn, int valid, int ready, int last,
                                          const svBitVecVal* data, const svBitVecVal* keep,
                                          const svBitVecVal* user) {
    Port* p = find(port);
    if (!p) return 0;
    p->cycles++;
    const bool pause = paused(*p);
    if (!resetn) {
        p->partial = Packet();
        return 0;
    }
    int result = pause ? 0 : 1;
    if (valid && ready) {
        note_beat(*p);
        const int lanes = p->data_w / 8;
        for (int lane = 0; lane < lanes; lane++) {
            p->partial.data.push_back(static_cast<uint8_t>(data[lane / 4] >> (8 * (lane % 4))));
            p->partial.keep.push_back(p->has_keep ? (keep[lane / 32] >> (lane % 32)) & 1 : 1);
        }
        p->partial.user.push_back(static_cast<uint64_t>(user[0]) |
                                  static_cast<uint64_t>(user[1]) << 32);
        if (last) {
            p->packets++;
            p->done.push_back(std::move(p->partial));
            p->partial = Packet();
            result |= 2;
        }
    } else if (valid) {
        p->stalls++;
    }
    return result;
}
