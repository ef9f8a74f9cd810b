#pragma once
// gRPC server reflection (grpc.reflection.v1alpha, proto/grpc/reflection/v1alpha) behind the
// daemon's credentials: the same authorization as every Station call is checked before
// anything is answered, so that the API's schema is not handed to whoever reaches the port.
// gRPC's reflection plugin serves every caller and has no hook for a check.
//
// Answers from the process's generated descriptor pool: list_services (the names given),
// file_by_filename, file_containing_symbol, file_containing_extension (each with the files
// the file imports, once per request) and all_extension_numbers_of_type; a name the pool
// does not know is an ErrorResponse NOT_FOUND in the stream, as gRPC's own service does.

#include <grpcpp/grpcpp.h>

#include <functional>
#include <string>
#include <vector>

#include "grpc/reflection/v1alpha/reflection.grpc.pb.h"

namespace linecal {

class ReflectionService final : public grpc::reflection::v1alpha::ServerReflection::Service {
 public:
  // `authorize` decides each call before anything is read (OK or the status to end it with);
  // `services` are the full names list_services reports.
  ReflectionService(std::function<grpc::Status(const grpc::ServerContext&)> authorize,
                    std::vector<std::string> services);

  grpc::Status ServerReflectionInfo(
      grpc::ServerContext* context,
      grpc::ServerReaderWriter<grpc::reflection::v1alpha::ServerReflectionResponse,
                               grpc::reflection::v1alpha::ServerReflectionRequest>* stream)
      override;

 private:
  void Answer(const grpc::reflection::v1alpha::ServerReflectionRequest& request,
              grpc::reflection::v1alpha::ServerReflectionResponse* response) const;

  std::function<grpc::Status(const grpc::ServerContext&)> authorize_;
  std::vector<std::string> services_;
};

}  // namespace linecal
