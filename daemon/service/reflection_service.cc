#include "daemon/service/reflection_service.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>

#include <set>

namespace linecal {
namespace {

namespace pb = google::protobuf;
using grpc::reflection::v1alpha::ServerReflectionRequest;
using grpc::reflection::v1alpha::ServerReflectionResponse;

void SetError(grpc::StatusCode code, const char* message, ServerReflectionResponse* response) {
  response->mutable_error_response()->set_error_code(static_cast<int32_t>(code));
  response->mutable_error_response()->set_error_message(message);
}

// `file` and, depth first, the files it imports, each once (`sent`): a client resolves the
// types a file uses without asking for every import.
void AddFile(const pb::FileDescriptor* file, std::set<std::string>* sent,
             ServerReflectionResponse* response) {
  if (!sent->insert(file->name()).second) return;
  pb::FileDescriptorProto proto;
  file->CopyTo(&proto);
  response->mutable_file_descriptor_response()->add_file_descriptor_proto(
      proto.SerializeAsString());
  for (int i = 0; i < file->dependency_count(); ++i) AddFile(file->dependency(i), sent, response);
}

}  // namespace

ReflectionService::ReflectionService(
    std::function<grpc::Status(const grpc::ServerContext&)> authorize,
    std::vector<std::string> services)
    : authorize_(std::move(authorize)), services_(std::move(services)) {}

grpc::Status ReflectionService::ServerReflectionInfo(
    grpc::ServerContext* context,
    grpc::ServerReaderWriter<ServerReflectionResponse, ServerReflectionRequest>* stream) {
  if (grpc::Status auth = authorize_(*context); !auth.ok()) return auth;
  ServerReflectionRequest request;
  while (stream->Read(&request)) {
    ServerReflectionResponse response;
    response.set_valid_host(request.host());
    *response.mutable_original_request() = request;
    Answer(request, &response);
    if (!stream->Write(response)) break;
  }
  return grpc::Status::OK;
}

void ReflectionService::Answer(const ServerReflectionRequest& request,
                               ServerReflectionResponse* response) const {
  const pb::DescriptorPool* pool = pb::DescriptorPool::generated_pool();
  std::set<std::string> sent;
  // The messages name no request value: a long one would make a long answer (issue 21).
  switch (request.message_request_case()) {
    case ServerReflectionRequest::kListServices:
      for (const std::string& name : services_) {
        response->mutable_list_services_response()->add_service()->set_name(name);
      }
      return;
    case ServerReflectionRequest::kFileByFilename: {
      const pb::FileDescriptor* file = pool->FindFileByName(request.file_by_filename());
      if (file == nullptr) return SetError(grpc::StatusCode::NOT_FOUND, "file not found", response);
      return AddFile(file, &sent, response);
    }
    case ServerReflectionRequest::kFileContainingSymbol: {
      const pb::FileDescriptor* file =
          pool->FindFileContainingSymbol(request.file_containing_symbol());
      if (file == nullptr)
        return SetError(grpc::StatusCode::NOT_FOUND, "symbol not found", response);
      return AddFile(file, &sent, response);
    }
    case ServerReflectionRequest::kFileContainingExtension: {
      const pb::Descriptor* type =
          pool->FindMessageTypeByName(request.file_containing_extension().containing_type());
      const pb::FieldDescriptor* extension =
          type == nullptr ? nullptr
                          : pool->FindExtensionByNumber(
                                type, request.file_containing_extension().extension_number());
      if (extension == nullptr)
        return SetError(grpc::StatusCode::NOT_FOUND, "extension not found", response);
      return AddFile(extension->file(), &sent, response);
    }
    case ServerReflectionRequest::kAllExtensionNumbersOfType: {
      const pb::Descriptor* type =
          pool->FindMessageTypeByName(request.all_extension_numbers_of_type());
      if (type == nullptr) return SetError(grpc::StatusCode::NOT_FOUND, "type not found", response);
      std::vector<const pb::FieldDescriptor*> extensions;
      pool->FindAllExtensions(type, &extensions);
      response->mutable_all_extension_numbers_response()->set_base_type_name(type->full_name());
      for (const pb::FieldDescriptor* e : extensions) {
        response->mutable_all_extension_numbers_response()->add_extension_number(e->number());
      }
      return;
    }
    case ServerReflectionRequest::MESSAGE_REQUEST_NOT_SET:
      break;
  }
  SetError(grpc::StatusCode::UNIMPLEMENTED, "no request in the message", response);
}

}  // namespace linecal
