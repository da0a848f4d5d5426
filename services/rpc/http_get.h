// A plain HTTP GET (libcurl) for reading a coordinator's Prometheus /metrics
// (`carvemap watch --metrics`, tests). Not for anything that needs authentication.
#ifndef CARVEMAP_SERVICES_RPC_HTTP_GET_H_
#define CARVEMAP_SERVICES_RPC_HTTP_GET_H_

#include <string>

#include "absl/status/statusor.h"

namespace carvemap {

// `url` may omit the scheme and path: "host:port" means http://host:port/metrics.
// UNAVAILABLE (naming the URL) when nothing answers, NOT_FOUND for a 404, INTERNAL for other
// HTTP errors.
absl::StatusOr<std::string> HttpGet(const std::string& url, double timeout_s);

}  // namespace carvemap

#endif  // CARVEMAP_SERVICES_RPC_HTTP_GET_H_
