// The large buffers a run frees are kept for the next buffer of their size (core/tile.h, allocate_buffer:
// up to 512 MB). A process that makes many runs of different shapes (a dataset's samples) releases them
// after each, so that it holds no more than the sample at hand needs.
#pragma once

namespace spadgen {

// Unmaps the freed buffers kept for reuse. Safe at any time (buffers in use are not touched).
void release_cached_buffers() noexcept;

}  // namespace spadgen
