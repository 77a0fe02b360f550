// The C++ side of rosgate_gmii_tap (gmii_tap.sv): frames between a TAP device and a design's
// GMII port, a byte per clock edge, without Python. Python (host.compiled.gmii_tap) attaches
// the TAP file descriptor and reads the counters through ctypes. The framing (preamble, SFD,
// gap, minimum frame, FCS polynomial, the IPv6 EtherType it counts) comes as ROSGATE_GMII_*
// defines from hdl.net.frames and hdl.net.crc (host.compiled.gmii_tap.GMII_TAP_LINK_ARGS).

#include <unistd.h>

#include <cstdint>
#include <deque>
#include <vector>

namespace {

#ifndef ROSGATE_GMII_PREAMBLE
#error "build with host.compiled.gmii_tap.GMII_TAP_LINK_ARGS (the ROSGATE_GMII_* framing)"
#endif

const int MAX_PORTS = 8;
const size_t PREAMBLE = ROSGATE_GMII_PREAMBLE;          // preamble bytes before the SFD
const uint8_t PREAMBLE_BYTE = ROSGATE_GMII_PREAMBLE_BYTE;
const uint8_t SFD = ROSGATE_GMII_SFD;
const int IFG_CYCLES = ROSGATE_GMII_IFG;
const size_t MIN_FRAME = ROSGATE_GMII_MIN_FRAME - 4;     // bytes before the FCS
const uint32_t CRC32_POLY_REFLECTED = ROSGATE_GMII_CRC32_POLY_REFLECTED;
const uint16_t ETHERTYPE_IPV6 = ROSGATE_GMII_ETHERTYPE_IPV6;
const int FRAMES_PER_POLL = 8;

enum Stat { TO_DESIGN, FROM_DESIGN, DROPPED, IPV6, BAD_FCS, STATS };

struct Port {
    int fd = -1;
    uint32_t poll_cycles = 64;
    uint32_t since_poll = 0;
    std::deque<std::vector<uint8_t>> queue;   // kernel frames waiting, as sent on the wire
    std::vector<uint8_t> sending;
    size_t pos = 0;
    int ifg = 0;
    std::vector<uint8_t> receiving;             // the design's frame so far
    bool in_frame = false;
    bool error = false;
    uint64_t stats[STATS] = {};
};

Port ports[MAX_PORTS];
uint32_t crc_table[256];

void make_crc_table() {
    for (uint32_t n = 0; n < 256; n++) {
        uint32_t c = n;
        for (int k = 0; k < 8; k++) c = c & 1 ? CRC32_POLY_REFLECTED ^ (c >> 1) : c >> 1;
        crc_table[n] = c;
    }
}

uint32_t crc32(const uint8_t* data, size_t len) {
    uint32_t c = 0xffffffffu;
    for (size_t i = 0; i < len; i++) c = crc_table[(c ^ data[i]) & 0xff] ^ (c >> 8);
    return c ^ 0xffffffffu;
}

std::vector<uint8_t> on_the_wire(const uint8_t* frame, size_t len) {
    std::vector<uint8_t> wire(PREAMBLE, PREAMBLE_BYTE);
    wire.push_back(SFD);
    wire.insert(wire.end(), frame, frame + len);
    while (wire.size() < PREAMBLE + 1 + MIN_FRAME) wire.push_back(0);
    const uint32_t fcs = crc32(wire.data() + PREAMBLE + 1, wire.size() - PREAMBLE - 1);
    for (int k = 0; k < 4; k++) wire.push_back((fcs >> (8 * k)) & 0xff);
    return wire;
}

void poll(Port& p) {
    uint8_t buffer[2048];
    for (int i = 0; i < FRAMES_PER_POLL; i++) {
        const ssize_t n = read(p.fd, buffer, sizeof buffer);
        if (n <= 0) break;
        if (n >= 14 && ((buffer[12] << 8) | buffer[13]) == ETHERTYPE_IPV6) p.stats[IPV6]++;
        p.stats[TO_DESIGN]++;
        p.queue.push_back(on_the_wire(buffer, static_cast<size_t>(n)));
    }
}

void frame_ended(Port& p) {
    const std::vector<uint8_t>& f = p.receiving;
    size_t i = 0;
    while (i < f.size() && f[i] == PREAMBLE_BYTE) i++;
    const bool framed = i < f.size() && f[i] == SFD && f.size() - i - 1 >= 4;
    if (!framed || p.error) {
        p.stats[BAD_FCS]++;
        return;
    }
    const uint8_t* body = f.data() + i + 1;
    const size_t len = f.size() - i - 1 - 4;
    const uint32_t fcs = body[len] | body[len + 1] << 8 | body[len + 2] << 16
                         | static_cast<uint32_t>(body[len + 3]) << 24;
    if (crc32(body, len) != fcs) {
        p.stats[BAD_FCS]++;
        return;
    }
    p.stats[FROM_DESIGN]++;
    if (p.fd >= 0 && write(p.fd, body, len) < 0) p.stats[DROPPED]++;
}

}  // namespace

extern "C" {

// Attach TAP file descriptor `fd` (non-blocking) to port `port`, polled every `poll_cycles`
// receive clock cycles while idle. Returns 0, or -1 for a bad port.
int rosgate_gmii_tap_attach(int port, int fd, int poll_cycles) {
    if (port < 0 || port >= MAX_PORTS || poll_cycles <= 0) return -1;
    if (!crc_table[1]) make_crc_table();
    ports[port].fd = fd;
    ports[port].poll_cycles = static_cast<uint32_t>(poll_cycles);
    return 0;
}

// Counter `which` of port `port`: 0 frames to the design, 1 frames from it, 2 frames the TAP
// device did not take, 3 IPv6 frames from the kernel, 4 design frames with a bad FCS or TX_ER.
uint64_t rosgate_gmii_tap_stat(int port, int which) {
    if (port < 0 || port >= MAX_PORTS || which < 0 || which >= STATS) return 0;
    return ports[port].stats[which];
}

int rosgate_gmii_tap_rx(int port) {
    Port& p = ports[port];
    if (p.pos < p.sending.size()) {
        const int byte = p.sending[p.pos++];
        if (p.pos == p.sending.size()) p.ifg = IFG_CYCLES;
        return 0x100 | byte;
    }
    if (p.ifg > 0) {
        p.ifg--;
        return 0;
    }
    if (p.fd >= 0 && ++p.since_poll >= p.poll_cycles) {
        p.since_poll = 0;
        poll(p);
    }
    if (p.queue.empty()) return 0;
    p.sending = std::move(p.queue.front());
    p.queue.pop_front();
    p.pos = 0;
    const int byte = p.sending[p.pos++];
    return 0x100 | byte;
}

void rosgate_gmii_tap_tx(int port, int data, int en, int er) {
    Port& p = ports[port];
    if (en) {
        if (!p.in_frame) {
            p.in_frame = true;
            p.error = false;
            p.receiving.clear();
        }
        p.receiving.push_back(static_cast<uint8_t>(data));
        if (er) p.error = true;
    } else if (p.in_frame) {
        p.in_frame = false;
        frame_ended(p);
    }
}

}  // extern "C"
