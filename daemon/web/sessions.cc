#include "daemon/web/sessions.h"

#include <openssl/crypto.h>
#include <openssl/rand.h>

#include <algorithm>
#include <array>

#include "absl/strings/escaping.h"

namespace linecal {
namespace {

// Constant time over the token's length: the time of a refusal says nothing about how many
// leading characters were right. An empty configured token matches nothing.
bool SameToken(const std::string& given, const std::string& configured) {
  return !configured.empty() && given.size() == configured.size() &&
         CRYPTO_memcmp(given.data(), configured.data(), configured.size()) == 0;
}

}  // namespace

const char* RoleName(Role role) { return role == Role::kOperator ? "operator" : "read-only"; }

Sessions::Sessions(std::string token, std::string operator_token)
    : token_(std::move(token)), operator_token_(std::move(operator_token)) {}

absl::StatusOr<std::string> Sessions::Login(const std::string& token, Clock::time_point now) {
  if (!login_possible())
    return absl::FailedPreconditionError("no login: the daemon has no auth_token");
  // Both compared, whichever matches: the time does not tell which token was tried.
  const bool reader = SameToken(token, token_);
  const bool op = SameToken(token, operator_token_);
  if (!reader && !op) return absl::PermissionDeniedError("token: not the daemon's auth_token");
  std::array<unsigned char, 32> bytes{};
  if (RAND_bytes(bytes.data(), static_cast<int>(bytes.size())) != 1) {
    return absl::InternalError("session: the random generator failed");
  }
  std::string id = absl::BytesToHexString(
      absl::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  std::lock_guard<std::mutex> lock(mutex_);
  if (sessions_.size() >= kMaxSessions) {
    const auto oldest = std::min_element(
        sessions_.begin(), sessions_.end(),
        [](const auto& a, const auto& b) { return a.second.last_used < b.second.last_used; });
    sessions_.erase(oldest);
  }
  sessions_[id] = {now, op ? Role::kOperator : Role::kReadOnly};
  return id;
}

const Sessions::Session* Sessions::Touch(const std::string& id, Clock::time_point now) {
  const auto it = sessions_.find(id);
  if (it == sessions_.end()) return nullptr;
  if (now - it->second.last_used > kSessionIdleLifetime) {
    sessions_.erase(it);
    return nullptr;
  }
  it->second.last_used = now;
  return &it->second;
}

bool Sessions::Check(const std::string& id, Clock::time_point now) {
  std::lock_guard<std::mutex> lock(mutex_);
  return Touch(id, now) != nullptr || !login_required();
}

Role Sessions::RoleOf(const std::string& id, Clock::time_point now) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Session* s = Touch(id, now);
  return s != nullptr ? s->role : Role::kReadOnly;
}

void Sessions::Logout(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  sessions_.erase(id);
}

size_t Sessions::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return sessions_.size();
}

}  // namespace linecal
