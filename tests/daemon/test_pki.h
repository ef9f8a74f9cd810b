#pragma once
// Certificates for the TLS tests, made at test time with the openssl command (Debian's
// `openssl` package): a CA, a server certificate for 127.0.0.1 and localhost, a client
// certificate from that CA, and a second CA with a client certificate of its own (one the
// server must refuse). EC P-256 keys: quick to make, and what gRPC's TLS stack handles.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace linecal::testing_daemon {

struct TestPki {
  std::string ca_cert;      // the CA of the server and of `client`
  std::string server_cert;  // SAN IP:127.0.0.1, DNS:localhost
  std::string server_key;
  std::string client_cert;  // signed by ca_cert
  std::string client_key;
  std::string other_ca_cert;      // an unrelated CA
  std::string other_client_cert;  // signed by other_ca_cert
  std::string other_client_key;
};

namespace pki_internal {

// Runs one openssl command in `dir`, its output to dir/openssl.log.
inline absl::Status OpenSsl(const std::filesystem::path& dir, const std::string& args) {
  const std::string command =
      absl::StrCat("cd '", dir.string(), "' && openssl ", args, " >>openssl.log 2>&1");
  if (std::system(command.c_str()) != 0) {
    return absl::InternalError(
        absl::StrCat("openssl ", args, " failed, see ", (dir / "openssl.log").string()));
  }
  return absl::OkStatus();
}

// A CA: self-signed, allowed to sign (req -x509 applies the default config's v3_ca section).
inline absl::Status MakeCa(const std::filesystem::path& dir, const std::string& name) {
  return OpenSsl(
      dir,
      absl::StrCat(
          "req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 -subj '/CN=",
          name, "' -keyout ", name, ".key -out ", name, ".pem"));
}

// A key and a certificate signed by `ca` with the extensions in `extensions` (one per line).
inline absl::Status MakeLeaf(const std::filesystem::path& dir, const std::string& name,
                             const std::string& ca, int serial, const std::string& extensions) {
  std::ofstream(dir / (name + ".ext")) << extensions;
  if (absl::Status s = OpenSsl(
          dir, absl::StrCat(
                   "req -new -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -subj '/CN=",
                   name, "' -keyout ", name, ".key -out ", name, ".csr"));
      !s.ok()) {
    return s;
  }
  return OpenSsl(dir, absl::StrCat("x509 -req -in ", name, ".csr -CA ", ca, ".pem -CAkey ", ca,
                                   ".key -set_serial ", serial, " -days 2 -extfile ", name,
                                   ".ext -out ", name, ".pem"));
}

}  // namespace pki_internal

// Makes the certificates in `dir` (which must exist) into `pki`; a failure names the openssl
// command and its log, for ASSERT_TRUE. Cost: about 150 ms of openssl runs.
inline ::testing::AssertionResult MakeTestPki(const std::filesystem::path& dir, TestPki* pki) {
  using pki_internal::MakeCa;
  using pki_internal::MakeLeaf;
  for (absl::Status s :
       {MakeCa(dir, "ca"), MakeCa(dir, "other_ca"),
        MakeLeaf(dir, "server", "ca", 1,
                 "subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth\n"),
        MakeLeaf(dir, "client", "ca", 2, "extendedKeyUsage=clientAuth\n"),
        MakeLeaf(dir, "other_client", "other_ca", 3, "extendedKeyUsage=clientAuth\n")}) {
    if (!s.ok()) return ::testing::AssertionFailure() << s.message();
  }
  auto at = [&](const std::string& file) { return (dir / file).string(); };
  *pki =
      TestPki{at("ca.pem"),     at("server.pem"),   at("server.key"),       at("client.pem"),
              at("client.key"), at("other_ca.pem"), at("other_client.pem"), at("other_client.key")};
  return ::testing::AssertionSuccess();
}

}  // namespace linecal::testing_daemon
