// The coordinator's side of MergeService (proto/carvemap/v1/merge.proto): a MergeFunction
// that runs a job's merge on a merge service (`carvemap merger`) instead of in the
// coordinator's process (docs/DESIGN.md §1, §8; docs/RPC.md "MergeService").
//
// One call = one bidirectional stream: the job goes out, progress comes back (handed to the
// request's `progress`), and the service's re-carve requests (§5.6.1) are answered with the
// request's `recarve` (the coordinator's workers carve them). Cancellation: `progress`
// returning false (it is also called every 250 ms) cancels the call, and the service stops
// the merge at its next step.
//
// A merge service lost mid-merge (killed, shut down, network cut: the stream ends without the
// merge's verdict) or not reachable within connect_timeout_s is one failed attempt: the whole
// merge runs again on the next address (round robin; with one address, the same service once
// it is back), up to `attempts`; then the job fails with the reason. A merge the service
// finished with an error (bad tiles, full disk) and a refusal (UNAUTHENTICATED: wrong secret)
// are not retried. Re-carved chunks are not carved twice: a retry asking for the same chunks
// and regions at the same resolution gets the earlier answer.
#ifndef CARVEMAP_SERVICES_RPC_MERGE_CLIENT_H_
#define CARVEMAP_SERVICES_RPC_MERGE_CLIENT_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "services/rpc/channel_security.h"
#include "services/rpc/merge_request.h"

namespace carvemap {

struct MergeClientSpec {
  // "host:port" of one or more merge services (in a cluster: the merge Service's name).
  std::vector<std::string> addresses;
  // `security.bearer` is the cluster secret; TLS settings as for any client, a client
  // certificate for mutual TLS.
  ChannelSecurity security;
  // Merge services lost (or unreachable) this many times in one job's merge: the job fails.
  int attempts = 3;
  // How long one attempt waits for a service to accept a connection, in seconds.
  double connect_timeout_s = 30.0;
  // Pause before the next attempt, in seconds.
  double retry_delay_s = 1.0;

  absl::Status Validate() const;
};

// Checks the spec and reads the TLS files now (errors name the file); the channels connect
// lazily. The function is thread-safe: the coordinator's jobs merge concurrently, each on its
// own call. Errors it returns: Cancelled (progress said stop); the service's verdict;
// Unauthenticated/PermissionDenied/InvalidArgument/Unimplemented when a service refused the
// call; Unavailable after `attempts` lost services ("merge service lost 3 times: ...").
absl::StatusOr<MergeFunction> RemoteMerge(MergeClientSpec spec);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_MERGE_CLIENT_H_
