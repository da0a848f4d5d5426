// The one place where absl::Status and grpc::Status meet (as tensorstore's
// AbslStatusToGrpcStatus). Services use absl::Status inside and convert at the RPC boundary.
#ifndef CARVEMAP_SERVICES_GRPC_STATUS_H_
#define CARVEMAP_SERVICES_GRPC_STATUS_H_

#include <grpcpp/support/status.h>

#include "absl/status/status.h"

namespace carvemap {

// Same code (the numeric values of absl::StatusCode and grpc::StatusCode are both the
// canonical google.rpc.Code), same message. Payloads are dropped.
[[nodiscard]] grpc::Status ToGrpcStatus(const absl::Status& status);
[[nodiscard]] absl::Status FromGrpcStatus(const grpc::Status& status);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_GRPC_STATUS_H_
