// When a worker gives the memory its tasks freed back to the system (ReturnFreedMemory), as a
// plain decision the task loop asks, so that it can be tested without a worker.
#ifndef CARVEMAP_SERVICES_RPC_WORKER_MEMORY_POLICY_H_
#define CARVEMAP_SERVICES_RPC_WORKER_MEMORY_POLICY_H_

namespace carvemap {

// glibc keeps a finished task's freed sums and batches in its arenas, fragmented, and a later
// task's resident peak counts them again: with the same heap peak, a worker's resident memory
// grew with the slices' length (docs/BENCHMARKS.md "--laps 4"). So it gives them back after
// each slice (milliseconds against its seconds). Not after a combine: its buffers (one chunk's
// leaves) are what the next combine needs again, and giving them back took ~250 system calls
// per combine, then faulting the pages in again (docs/BENCHMARKS.md "The combines' system
// calls"). What the combines kept goes back once the coordinator has no task to give, so that
// an idle worker holds no more than after a slice.
class FreedMemoryPolicy {
 public:
  // A task ran (a slice, or a chunk's combine); true: give freed memory back now.
  bool AfterTask(bool slice) {
    kept_ = !slice;
    return slice;
  }
  // The coordinator had no task; true: give freed memory back now.
  bool WhenIdle() {
    const bool give_back = kept_;
    kept_ = false;
    return give_back;
  }

 private:
  bool kept_ = false;  // a combine's freed buffers are kept for the next task
};

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_WORKER_MEMORY_POLICY_H_
