// The storage of rosgate_axi_ram (axi_ram.sv): bytes the simulated AXI4 slave reads and
// writes through DPI-C, and that Python reads and writes in place through ctypes
// (host/compiled/__init__.py), in the same process as the Verilator model.
#include <cstdint>
#include <cstring>
#include <sys/mman.h>

#define ROSGATE_EXPORT extern "C" __attribute__((visibility("default"), used))

static uint8_t *ram_base = nullptr;
static uint64_t ram_size = 0;
static uint64_t ram_accesses = 0;

// Python: give the memory ``size`` zeroed bytes (pages are only backed once written).
ROSGATE_EXPORT uint8_t *rosgate_axi_ram_attach(uint64_t size) {
    if (ram_base != nullptr) {
        munmap(ram_base, ram_size);
        ram_base = nullptr;
        ram_size = 0;
    }
    void *base = mmap(nullptr, size, PROT_READ | PROT_WRITE,
                      MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (base == MAP_FAILED) return nullptr;
    ram_base = static_cast<uint8_t *>(base);
    ram_size = size;
    return ram_base;
}

// Python: word reads and writes of the bus so far (a measure of progress).
ROSGATE_EXPORT uint64_t rosgate_axi_ram_accesses() { return ram_accesses; }

// DPI: whether the ``nbytes`` at ``addr`` are inside the memory (else the slave answers
// SLVERR, as an interconnect with nothing behind that address would).
ROSGATE_EXPORT unsigned char rosgate_axi_ram_present(uint64_t addr, uint32_t nbytes) {
    return ram_base != nullptr && addr < ram_size && nbytes <= ram_size - addr;
}

// DPI: ``nbytes`` (at most 8) little-endian bytes at ``addr``.
ROSGATE_EXPORT uint64_t rosgate_axi_ram_read(uint64_t addr, uint32_t nbytes) {
    uint64_t value = 0;
    ram_accesses++;
    if (rosgate_axi_ram_present(addr, nbytes)) memcpy(&value, ram_base + addr, nbytes);
    return value;
}

// DPI: the bytes of ``data`` whose bit is set in ``strb`` (of ``nbytes``, at most 8) to
// ``addr``.
ROSGATE_EXPORT void rosgate_axi_ram_write(uint64_t addr, uint64_t data, uint32_t strb,
                                          uint32_t nbytes) {
    ram_accesses++;
    if (!rosgate_axi_ram_present(addr, nbytes)) return;
    for (uint32_t i = 0; i < nbytes; i++)
        if (strb >> i & 1) ram_base[addr + i] = static_cast<uint8_t>(data >> (8 * i));
}
