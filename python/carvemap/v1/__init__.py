"""The gRPC stubs of proto/carvemap/v1/jobs.proto (jobs_pb2, jobs_pb2_grpc), generated when the
package is built (setup.py): protoc names them carvemap.v1 after the proto's path."""
