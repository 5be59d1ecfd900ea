// Files mapped into memory, by address, so that a SIGBUS in one of them is told as what it is: another
// process cut the file short while spadgen read it through its mapping (a `cp` over a run's counts.npy while
// `spadgen reconstruct` read it killed the process with SIGBUS, exit 135, without a word).
//
// Readers and writers that map a file register the mapping for as long as it lives; the program's SIGBUS
// handler (install_mapped_file_fault_handler, main() installs it) names the file whose mapping the faulting
// address lies in, and ends the process with exit 1 as an error: "spadgen: error: FILE was cut short ...".
// A SIGBUS outside every registered mapping keeps its default action (a crash, as it is).
#pragma once
#include <cstddef>
#include <string>

namespace spadgen {

// Registers [begin, begin + bytes) as a mapping of `path`; at most kMaxMappedFiles at once (beyond, the
// mapping is not named: its SIGBUS stays a crash). Thread-safe.
void register_mapped_file(const void* begin, size_t bytes, const std::string& path);
// Forgets the mapping that begins at `begin` (before it is unmapped). Thread-safe.
void unregister_mapped_file(const void* begin);
// Installs the SIGBUS handler (SA_SIGINFO, on the alternate stack when the thread has one).
void install_mapped_file_fault_handler();

inline constexpr int kMaxMappedFiles = 256;
inline constexpr size_t kMaxMappedPathBytes = 1024;  // longer paths are shortened in the message

}  // namespace spadgen
