// Starts a real server on localhost:0 with the health service and reflection on, and talks to
// it with a generic (untyped) client: Debian 12 ships neither the health nor the reflection
// .proto stubs, so the requests and answers are encoded by hand (both are a few bytes).
#include "services/rpc/grpc_server_common.h"

#include <grpcpp/create_channel.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_builder.h>
#include <grpcpp/support/byte_buffer.h>
#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "proto/carvemap/v1/carve.grpc.pb.h"
#include "proto/carvemap/v1/jobs.grpc.pb.h"
#include "services/rpc/grpc_status.h"

namespace carvemap {
namespace {

std::string ToString(const grpc::ByteBuffer& buffer) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(buffer.Dump(&slices).ok());
  std::string out;
  for (const grpc::Slice& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}

grpc::ByteBuffer ToBuffer(const std::string& bytes) {
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

// Waits for the next completion and checks it is `tag`.
bool Await(grpc::CompletionQueue& cq, void* tag) {
  void* got = nullptr;
  bool ok = false;
  EXPECT_TRUE(cq.Next(&got, &ok));
  EXPECT_EQ(got, tag);
  return ok;
}

// grpc.health.v1.HealthCheckRequest{service} → (status, HealthCheckResponse bytes).
std::pair<grpc::Status, std::string> HealthCheck(grpc::GenericStub& stub,
                                                 const std::string& service) {
  std::string request;
  if (!service.empty()) {  // field 1, length-delimited
    request.push_back(0x0a);
    request.push_back(static_cast<char>(service.size()));
    request += service;
  }
  grpc::ClientContext context;
  grpc::CompletionQueue cq;
  auto call = stub.PrepareUnaryCall(&context, "/grpc.health.v1.Health/Check", ToBuffer(request),
                                    &cq);
  call->StartCall();
  grpc::ByteBuffer response;
  grpc::Status status;
  call->Finish(&response, &status, reinterpret_cast<void*>(1));
  Await(cq, reinterpret_cast<void*>(1));
  return {status, status.ok() ? ToString(response) : ""};
}

class GrpcServerCommonTest : public ::testing::Test {
 protected:
  void SetUp() override {
    EnableHealthAndReflection();
    grpc::ServerBuilder builder;
    builder.AddListeningPort("localhost:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(&jobs_);  // all methods UNIMPLEMENTED; enough for reflection
    builder.RegisterService(&carve_);
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    ASSERT_GT(port_, 0);
    channel_ = grpc::CreateChannel("localhost:" + std::to_string(port_),
                                   grpc::InsecureChannelCredentials());
  }
  void TearDown() override {
    if (server_) server_->Shutdown();
  }

  int port_ = 0;
  carvemap::v1::JobService::Service jobs_;
  carvemap::v1::CarveTaskService::Service carve_;
  std::unique_ptr<grpc::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
};

// HealthCheckResponse{status: SERVING=1} is field 1 varint 1: 08 01; NOT_SERVING=2: 08 02.
const std::string kServing("\x08\x01", 2);
const std::string kNotServing("\x08\x02", 2);

TEST_F(GrpcServerCommonTest, HealthAnswersServing) {
  grpc::GenericStub stub(channel_);
  auto [status, response] = HealthCheck(stub, "");
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(response, kServing);
}

TEST_F(GrpcServerCommonTest, PerServiceStatusFollowsSetServing) {
  grpc::GenericStub stub(channel_);
  SetServing(*server_, "carvemap.v1.JobService", true);
  EXPECT_EQ(HealthCheck(stub, "carvemap.v1.JobService").second, kServing);
  SetServing(*server_, "carvemap.v1.JobService", false);
  EXPECT_EQ(HealthCheck(stub, "carvemap.v1.JobService").second, kNotServing);
  // A service never registered with the health service is NOT_FOUND (standard protocol).
  EXPECT_EQ(HealthCheck(stub, "no.such.Service").first.error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(GrpcServerCommonTest, ReflectionListsCarvemapServices) {
  grpc::GenericStub stub(channel_);
  grpc::ClientContext context;
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(
      &context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  call->StartCall(reinterpret_cast<void*>(1));
  ASSERT_TRUE(Await(cq, reinterpret_cast<void*>(1)));
  // ServerReflectionRequest{list_services: "*"}: field 7, length-delimited.
  call->Write(ToBuffer(std::string("\x3a\x01*", 3)), reinterpret_cast<void*>(2));
  ASSERT_TRUE(Await(cq, reinterpret_cast<void*>(2)));
  call->WritesDone(reinterpret_cast<void*>(3));
  ASSERT_TRUE(Await(cq, reinterpret_cast<void*>(3)));
  grpc::ByteBuffer response;
  call->Read(&response, reinterpret_cast<void*>(4));
  ASSERT_TRUE(Await(cq, reinterpret_cast<void*>(4)));
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  Await(cq, reinterpret_cast<void*>(5));
  ASSERT_TRUE(status.ok()) << status.error_message();
  const std::string bytes = ToString(response);
  EXPECT_NE(bytes.find("carvemap.v1.JobService"), std::string::npos);
  EXPECT_NE(bytes.find("carvemap.v1.CarveTaskService"), std::string::npos);
  EXPECT_NE(bytes.find("grpc.health.v1.Health"), std::string::npos);
}

TEST_F(GrpcServerCommonTest, UnimplementedMethodAnswersUnimplemented) {
  auto stub = carvemap::v1::JobService::NewStub(channel_);
  grpc::ClientContext context;
  carvemap::v1::GetJobRequest request;
  request.set_job_id("j-1");
  carvemap::v1::Job job;
  absl::Status status = FromGrpcStatus(stub->GetJob(&context, request, &job));
  EXPECT_EQ(status.code(), absl::StatusCode::kUnimplemented);
}

// GetJob answers NOT_FOUND, so a call tells which server it reached (an unknown service is
// UNIMPLEMENTED).
class NotFoundJobs final : public carvemap::v1::JobService::Service {
  grpc::Status GetJob(grpc::ServerContext*, const carvemap::v1::GetJobRequest*,
                      carvemap::v1::Job*) override {
    return grpc::Status(grpc::StatusCode::NOT_FOUND, "no job");
  }
};

// StartGrpcServer: the services on the main port; health alone on the plaintext health port;
// MarkServing and Shutdown reach both.
TEST(StartGrpcServerTest, ServesAndStopsBothPorts) {
  NotFoundJobs jobs;
  GrpcServerSpec spec;
  spec.component = "test";
  spec.listen_address = "localhost:0";
  spec.credentials = grpc::InsecureServerCredentials();
  spec.services = {&jobs};
  spec.health_listen_address = "localhost:0";
  absl::StatusOr<GrpcServers> servers = StartGrpcServer(spec);
  ASSERT_TRUE(servers.ok()) << servers.status();
  ASSERT_GT(servers->port, 0);
  ASSERT_GT(servers->health_port, 0);
  ASSERT_NE(servers->port, servers->health_port);
  servers->MarkServing({"carvemap.v1.JobService"});
  for (int port : {servers->port, servers->health_port}) {
    grpc::GenericStub stub(grpc::CreateChannel("localhost:" + std::to_string(port),
                                               grpc::InsecureChannelCredentials()));
    EXPECT_EQ(HealthCheck(stub, "").second, kServing) << port;
    EXPECT_EQ(HealthCheck(stub, "carvemap.v1.JobService").second, kServing) << port;
  }
  // The job API is on the main port only.
  for (auto [port, code] : {std::pair{servers->port, absl::StatusCode::kNotFound},
                            std::pair{servers->health_port, absl::StatusCode::kUnimplemented}}) {
    auto stub = carvemap::v1::JobService::NewStub(grpc::CreateChannel(
        "localhost:" + std::to_string(port), grpc::InsecureChannelCredentials()));
    grpc::ClientContext context;
    carvemap::v1::GetJobRequest request;
    carvemap::v1::Job job;
    EXPECT_EQ(FromGrpcStatus(stub->GetJob(&context, request, &job)).code(), code) << port;
  }
  servers->Shutdown(std::chrono::milliseconds(100));
  grpc::GenericStub stub(grpc::CreateChannel("localhost:" + std::to_string(servers->port),
                                             grpc::InsecureChannelCredentials()));
  EXPECT_FALSE(HealthCheck(stub, "").first.ok());
}

TEST(StartGrpcServerTest, AnAddressThatCannotBeBoundIsUnavailable) {
  GrpcServerSpec spec;
  spec.component = "test";
  spec.listen_address = "192.0.2.1:0";  // TEST-NET-1: no interface of this machine has it
  spec.credentials = grpc::InsecureServerCredentials();
  absl::StatusOr<GrpcServers> servers = StartGrpcServer(spec);
  EXPECT_EQ(servers.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(servers.status().message(), "test: cannot listen on 192.0.2.1:0");
  spec.listen_address = "localhost:0";
  spec.health_listen_address = "192.0.2.1:0";
  servers = StartGrpcServer(spec);
  EXPECT_EQ(servers.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(servers.status().message(), "test: cannot listen on 192.0.2.1:0 (health)");
}

TEST(GrpcStatusTest, RoundTripsEveryCode) {
  for (int code = 0; code <= 16; ++code) {
    absl::Status in(static_cast<absl::StatusCode>(code), code == 0 ? "" : "chunk (1,2,3): x");
    grpc::Status mid = ToGrpcStatus(in);
    EXPECT_EQ(static_cast<int>(mid.error_code()), code);
    EXPECT_EQ(FromGrpcStatus(mid), in);
  }
}

}  // namespace
}  // namespace carvemap
