#pragma once
// The console's logins (docs/console.md, "Login"): a browser that posts the daemon's
// auth_token gets a session id, which its cookie carries from then on; the token itself
// never goes into a cookie, so a stolen cookie is worth one session, not the station's
// credential. Sessions live in memory only: a restart of linecald logs everyone out.
//
// Roles (docs/console.md, "Login and roles"): a login with the daemon's auth_token opens a
// read-only session, one with web.operator_token an operator session, which may also start
// and cancel cycles. The two tokens differ (the configuration refuses equal ones).
// Thread safety: every method may be called from any thread.

#include <chrono>
#include <cstddef>
#include <map>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"

namespace linecal {

// How long a session lives unused: a shift and a half, so that the station's screen, which
// keeps its live page open, never asks the operator to log in during a shift.
inline constexpr std::chrono::hours kSessionIdleLifetime{12};
// Sessions kept at most; the least recently used is dropped beyond it, so that a script
// logging in again and again cannot grow the daemon's memory. 1024: far beyond the screens
// and engineers of one station.
inline constexpr size_t kMaxSessions = 1024;

enum class Role { kReadOnly, kOperator };
// "read-only", "operator": the words of /api/session and /api/login.
const char* RoleName(Role role);

class Sessions {
 public:
  using Clock = std::chrono::steady_clock;

  // `token` empty: the daemon has no auth_token, and no login is needed to read (as for
  // gRPC). `operator_token` empty: no operator sessions.
  explicit Sessions(std::string token, std::string operator_token = "");

  bool login_required() const { return !token_.empty(); }
  // Whether some token opens a session (else /api/login has nothing to check).
  bool login_possible() const { return !token_.empty() || !operator_token_.empty(); }
  // A new session when `token` is the daemon's auth_token (read-only) or the operator token
  // (each compared in constant time): its id, 64 hexadecimal digits of OpenSSL's RAND_bytes
  // (256 bits). FailedPrecondition when no token is configured; PermissionDenied for any
  // other token; Internal when the random generator fails. `now` is for tests.
  absl::StatusOr<std::string> Login(const std::string& token, Clock::time_point now = Clock::now());
  // Whether `id` is a live session (always true when no login is required); a live one's
  // idle time starts again. O(log sessions).
  bool Check(const std::string& id, Clock::time_point now = Clock::now());
  // The role of `id`: kOperator for a live operator session, else kReadOnly (also for
  // unknown ids; Check says whether it may read). Refreshes a live one as Check does.
  Role RoleOf(const std::string& id, Clock::time_point now = Clock::now());
  // Ends the session `id` (nothing when it is unknown).
  void Logout(const std::string& id);
  size_t size() const;

 private:
  struct Session {
    Clock::time_point last_used;
    Role role = Role::kReadOnly;
  };
  // The live session `id` (its idle time started again), or null; under mutex_.
  const Session* Touch(const std::string& id, Clock::time_point now);

  const std::string token_;
  const std::string operator_token_;
  mutable std::mutex mutex_;
  std::map<std::string, Session> sessions_;  // by session id
};

}  // namespace linecal
