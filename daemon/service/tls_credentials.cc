#include "daemon/service/tls_credentials.h"

#include <grpcpp/security/server_credentials.h>
#include <openssl/bio.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

struct BioFree {
  void operator()(BIO* b) const { BIO_free(b); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct KeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};
using Bio = std::unique_ptr<BIO, BioFree>;
using Certificate = std::unique_ptr<X509, X509Free>;
using PrivateKey = std::unique_ptr<EVP_PKEY, KeyFree>;

Bio MemoryBio(const std::string& pem) {
  return Bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
}

// OpenSSL's reason for the last failure on this thread (and the queue emptied, so that a later
// check does not report a stale one).
std::string OpenSslReason() {
  const unsigned long code = ERR_get_error();  // NOLINT(runtime/int): OpenSSL's type
  ERR_clear_error();
  if (code == 0) return "no PEM data";
  char text[256];  // ERR_error_string(3)'s documented size; _n truncates longer ones
  ERR_error_string_n(code, text, sizeof text);
  return text;
}

absl::Status Invalid(const char* key, const std::string& path, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat("tls.", key, ": ", path, ": ", what));
}

}  // namespace

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerTlsCredentials(
    const TlsConfig& tls) {
  ERR_clear_error();
  Bio cert_bio = MemoryBio(tls.cert_pem);
  const Certificate cert(PEM_read_bio_X509(cert_bio.get(), nullptr, nullptr, nullptr));
  if (!cert)
    return Invalid("cert", tls.cert_path, "not a PEM certificate (" + OpenSslReason() + ")");
  Bio key_bio = MemoryBio(tls.key_pem);
  const PrivateKey key(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, nullptr, nullptr));
  if (!key)
    return Invalid("key", tls.key_path,
                   "not a PEM private key without passphrase (" + OpenSslReason() + ")");
  if (X509_check_private_key(cert.get(), key.get()) != 1) {
    ERR_clear_error();
    return Invalid(
        "key", tls.key_path,
        absl::StrCat("does not match the certificate of tls.cert (", tls.cert_path, ")"));
  }
  grpc::SslServerCredentialsOptions options(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  if (!tls.client_ca_path.empty()) {
    Bio ca_bio = MemoryBio(tls.client_ca_pem);
    const Certificate ca(PEM_read_bio_X509(ca_bio.get(), nullptr, nullptr, nullptr));
    if (!ca)
      return Invalid("client_ca", tls.client_ca_path,
                     "not a PEM certificate (" + OpenSslReason() + ")");
    options.pem_root_certs = tls.client_ca_pem;
    options.client_certificate_request =
        tls.require_client_cert ? GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY
                                : GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  options.pem_key_cert_pairs.push_back({tls.key_pem, tls.cert_pem});
  return grpc::SslServerCredentials(options);
}

}  // namespace linecal
