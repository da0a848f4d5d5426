// MergeParams (services/merge/merge_params.h) to and from the MergeJob message
// (proto/carvemap/v1/merge.proto): the one place the merge's parameters cross the wire.
#ifndef CARVEMAP_SERVICES_RPC_MERGE_PARAMS_PROTO_H_
#define CARVEMAP_SERVICES_RPC_MERGE_PARAMS_PROTO_H_

#include "services/merge/merge_params.h"

namespace carvemap::v1 {
class MergeJob;
}  // namespace carvemap::v1

namespace carvemap {

// Sets MergeJob's parameter fields; the others (job id, folders, job_json, ...) are the caller's.
void MergeParamsToProto(const MergeParams& params, v1::MergeJob* job);
// The message's zero values read as MergeParams's defaults ("" floor-plan method: "rooms");
// not validated here (RunMerge does, naming the field).
[[nodiscard]] MergeParams MergeParamsFromProto(const v1::MergeJob& job);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_MERGE_PARAMS_PROTO_H_
