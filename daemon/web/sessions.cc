#include "daemon/web/sessions.h"

#include <openssl/crypto.h>
#include <openssl/rand.h>

#include <algorithm>
#include <array>

#include "absl/strings/escaping.h"

namespace linecal {

Sessions::Sessions(std::string token) : token_(std::move(token)) {}

absl::StatusOr<std::string> Sessions::Login(const std::string& token, Clock::time_point now) {
  if (!login_required())
    return absl::FailedPreconditionError("no login: the daemon has no auth_token");
  // Constant time over the token's length: the time of a refusal says nothing about how
  // many leading characters were right.
  const bool match = token.size() == token_.size() &&
                     CRYPTO_memcmp(token.data(), token_.data(), token_.size()) == 0;
  if (!match) return absl::PermissionDeniedError("token: not the daemon's auth_token");
  std::array<unsigned char, 32> bytes{};
  if (RAND_bytes(bytes.data(), static_cast<int>(bytes.size())) != 1) {
    return absl::InternalError("session: the random generator failed");
  }
  std::string id = absl::BytesToHexString(
      absl::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  std::lock_guard<std::mutex> lock(mutex_);
  if (last_used_.size() >= kMaxSessions) {
    const auto oldest =
        std::min_element(last_used_.begin(), last_used_.end(),
                         [](const auto& a, const auto& b) { return a.second < b.second; });
    last_used_.erase(oldest);
  }
  last_used_[id] = now;
  return id;
}

bool Sessions::Check(const std::string& id, Clock::time_point now) {
  if (!login_required()) return true;
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = last_used_.find(id);
  if (it == last_used_.end()) return false;
  if (now - it->second > kSessionIdleLifetime) {
    last_used_.erase(it);
    return false;
  }
  it->second = now;
  return true;
}

void Sessions::Logout(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  last_used_.erase(id);
}

size_t Sessions::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_used_.size();
}

}  // namespace linecal
