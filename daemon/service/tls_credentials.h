#pragma once
// gRPC server credentials from the configuration's `tls` (daemon/core/daemon_config.h).

#include <grpcpp/security/server_credentials.h>

#include <memory>

#include "absl/status/statusor.h"
#include "daemon/core/daemon_config.h"

namespace linecal {

// TLS server credentials: the certificate chain and key of `tls`, and with a client_ca the
// clients' certificates asked for and verified against it (required, so that a client without
// one fails the handshake, when require_client_cert). Before gRPC sees them the PEM texts are
// parsed and the key is checked against the certificate, so that a wrong file is an error at
// start-up rather than a failed handshake later: InvalidArgument naming the key (tls.cert,
// tls.key, tls.client_ca) and the file. Cost: parses the PEM texts, microseconds.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerTlsCredentials(const TlsConfig& tls);

}  // namespace linecal
