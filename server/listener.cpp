#include "server/listener.h"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <chrono>
#include <cstring>

#include <spdlog/spdlog.h>

#include "server/port_owner.h"

namespace animspace::server {
namespace {

struct HostPort {
  std::string host;  // empty: every local address
  int port = 0;
};

Result<HostPort> parse_address(const std::string& address) {
  const auto invalid = [&](const std::string& why) {
    return make_error(ErrorCode::kInvalidArgument, "--listen: '" + address + "': " + why);
  };
  HostPort parsed;
  std::string port_text;
  if (!address.empty() && address.front() == '[') {
    const auto close = address.find(']');
    if (close == std::string::npos || close + 1 >= address.size() || address[close + 1] != ':') {
      return invalid("expected [v6 address]:port");
    }
    parsed.host = address.substr(1, close - 1);
    port_text = address.substr(close + 2);
  } else {
    const auto colon = address.rfind(':');
    if (colon == std::string::npos) return invalid("expected host:port");
    parsed.host = address.substr(0, colon);
    port_text = address.substr(colon + 1);
  }
  const auto [end, ec] = std::from_chars(port_text.data(), port_text.data() + port_text.size(), parsed.port);
  if (port_text.empty() || ec != std::errc{} || end != port_text.data() + port_text.size() || parsed.port < 0 ||
      parsed.port > 65535) {
    return invalid("the port must be a number from 0 to 65535, got '" + port_text + "'");
  }
  return parsed;
}

int port_of_socket(int socket) {
  sockaddr_storage address{};
  socklen_t length = sizeof address;
  if (::getsockname(socket, reinterpret_cast<sockaddr*>(&address), &length) != 0) return 0;
  if (address.ss_family == AF_INET) return ntohs(reinterpret_cast<sockaddr_in*>(&address)->sin_port);
  if (address.ss_family == AF_INET6) return ntohs(reinterpret_cast<sockaddr_in6*>(&address)->sin6_port);
  return 0;
}

void set_port(sockaddr* address, int port) {
  if (address->sa_family == AF_INET) reinterpret_cast<sockaddr_in*>(address)->sin_port = htons(static_cast<uint16_t>(port));
  if (address->sa_family == AF_INET6) {
    reinterpret_cast<sockaddr_in6*>(address)->sin6_port = htons(static_cast<uint16_t>(port));
  }
}

// Errors accept(2) says to treat like EAGAIN, retrying: the connection went away or the network
// hiccupped, not the listener.
bool transient_accept_error(int error_number) {
  switch (error_number) {
    case EINTR:
    case ECONNABORTED:
    case EPROTO:
    case ENETDOWN:
    case ENOPROTOOPT:
    case EHOSTDOWN:
    case ENONET:
    case EHOSTUNREACH:
    case EOPNOTSUPP:
    case ENETUNREACH:
    case EPERM:  // a firewall rule refused this one connection
      return true;
    default:
      return false;
  }
}

bool descriptor_limit(int error_number) {
  return error_number == EMFILE || error_number == ENFILE || error_number == ENOBUFS || error_number == ENOMEM;
}

}  // namespace

Result<std::unique_ptr<Listener>> Listener::bind(const std::string& listen_address) {
  auto parsed = parse_address(listen_address);
  if (!parsed) return parsed.error();
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* found = nullptr;
  const std::string service = std::to_string(parsed->port);
  if (const int failed = ::getaddrinfo(parsed->host.empty() ? nullptr : parsed->host.c_str(), service.c_str(),
                                       &hints, &found);
      failed != 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "--listen: '" + listen_address + "': cannot resolve '" + parsed->host + "': " + ::gai_strerror(failed));
  }
  bool has_v4 = false;
  for (const addrinfo* a = found; a != nullptr; a = a->ai_next) has_v4 = has_v4 || a->ai_family == AF_INET;

  std::vector<int> sockets;
  int port = parsed->port;
  int bind_error = 0;
  for (addrinfo* a = found; a != nullptr; a = a->ai_next) {
    if (a->ai_family != AF_INET && a->ai_family != AF_INET6) continue;
    const int socket = ::socket(a->ai_family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (socket < 0) {
      bind_error = errno;
      continue;
    }
    int yes = 1;
    ::setsockopt(socket, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    ::setsockopt(socket, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);  // inherited by accepted sockets
    if (a->ai_family == AF_INET6) {
      // "[::]:port" alone serves IPv4 too, as gRPC's listener does; beside an IPv4 address, IPv6 only.
      int v6_only = has_v4 ? 1 : 0;
      ::setsockopt(socket, IPPROTO_IPV6, IPV6_V6ONLY, &v6_only, sizeof v6_only);
    }
    set_port(a->ai_addr, port);  // port 0: the first socket's port for the others
    if (::bind(socket, a->ai_addr, a->ai_addrlen) != 0 || ::listen(socket, SOMAXCONN) != 0) {
      bind_error = errno;
      ::close(socket);
      if (bind_error == EADDRINUSE) break;
      continue;  // e.g. ::1 on a machine without IPv6: the other addresses serve
    }
    if (port == 0) port = port_of_socket(socket);
    sockets.push_back(socket);
  }
  ::freeaddrinfo(found);
  if (bind_error == EADDRINUSE || sockets.empty()) {
    for (const int socket : sockets) ::close(socket);
    const int busy_port = port != 0 ? port : parsed->port;
    if (bind_error == EADDRINUSE) {
      const auto owner = busy_port != 0 ? describe_tcp_listener(busy_port) : std::nullopt;
      return make_error(ErrorCode::kFailedPrecondition, "--listen: '" + listen_address + "' is already in use" +
                                                            (owner ? " by " + *owner : std::string()));
    }
    return make_error(ErrorCode::kInvalidArgument, "--listen: cannot bind '" + listen_address +
                                                       "': " + std::strerror(bind_error) + " (not a local address?)");
  }
  return std::unique_ptr<Listener>(new Listener(std::move(sockets), port, listen_address));
}

Listener::Listener(std::vector<int> sockets, int port, std::string address)
    : sockets_(std::move(sockets)), port_(port), address_(std::move(address)) {}

Listener::~Listener() { stop(); }

void Listener::start(std::unique_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor) {
  acceptor_ = std::move(acceptor);
  if (::pipe2(wake_, O_CLOEXEC | O_NONBLOCK) != 0) {
    // Without a wake pipe stop() could not interrupt the loop; poll's timeout then bounds it.
    wake_[0] = wake_[1] = -1;
  }
  reserve_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  thread_ = std::thread([this] { run(); });
}

void Listener::stop() {
  if (stopped_.exchange(true)) return;
  if (thread_.joinable()) {
    if (wake_[1] >= 0) {
      const char byte = 0;
      while (::write(wake_[1], &byte, 1) < 0 && errno == EINTR) {
      }
    }
    thread_.join();
  }
  for (const int socket : sockets_) ::close(socket);
  sockets_.clear();
  for (int& end : wake_) {
    if (end >= 0) ::close(end);
    end = -1;
  }
  if (reserve_ >= 0) ::close(reserve_);
  reserve_ = -1;
}

void Listener::run() {
  std::vector<pollfd> watched;
  watched.push_back({wake_[0], POLLIN, 0});
  for (const int socket : sockets_) watched.push_back({socket, POLLIN, 0});
  // Backing off: the limit could not be worked around (the reserve is gone too); look again
  // after a pause rather than spin on a socket that stays readable.
  constexpr int kBackOffMs = 100;
  constexpr int kNoWakePipeMs = 200;
  bool back_off = false;
  while (true) {
    const nfds_t count = back_off ? 1 : static_cast<nfds_t>(watched.size());
    const int timeout = back_off ? kBackOffMs : (wake_[0] < 0 ? kNoWakePipeMs : -1);
    const int ready = ::poll(watched.data(), count, timeout);
    if (ready < 0 && errno != EINTR) break;
    if (watched[0].revents != 0) break;  // stop()
    if (wake_[0] < 0 && stopped_) break;
    if (back_off) {
      back_off = false;
      if (reserve_ < 0) reserve_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
      continue;
    }
    for (size_t i = 1; i < watched.size(); ++i) {
      if (watched[i].revents != 0 && !accept_all(watched[i].fd)) back_off = true;
    }
  }
}

bool Listener::accept_all(int socket) {
  while (true) {
    const int connection = ::accept4(socket, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (connection >= 0) {
      grpc::experimental::ExternalConnectionAcceptor::NewConnectionParameters parameters;
      parameters.listener_fd = socket;
      parameters.fd = connection;  // gRPC owns it from here
      acceptor_->HandleNewConnection(&parameters);
      continue;
    }
    const int error_number = errno;
    if (error_number == EAGAIN || error_number == EWOULDBLOCK) return true;
    if (transient_accept_error(error_number)) continue;
    if (descriptor_limit(error_number)) {
      if (reserve_ < 0) return false;
      refuse_one(socket, error_number);
      continue;
    }
    spdlog::error("{}: accept failed: {}; trying again", address_, std::strerror(error_number));
    return false;
  }
}

void Listener::refuse_one(int socket, int error_number) {
  ::close(reserve_);
  reserve_ = -1;
  const int connection = ::accept4(socket, nullptr, nullptr, SOCK_CLOEXEC);
  if (connection >= 0) {
    ::close(connection);
    const uint64_t refused = refused_.fetch_add(1) + 1;
    // The first, then every hundredth: a client storm at the limit must not flood the log.
    if (refused == 1 || refused % 100 == 0) {
      spdlog::warn("{}: out of file descriptors ({}): {} connection(s) refused so far; the daemon serves again "
                   "once descriptors are free (raise `ulimit -n`)",
                   address_, std::strerror(error_number), refused);
    }
  }
  reserve_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
}

uint64_t raise_descriptor_limit() {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0) return 0;
  if (limit.rlim_cur < limit.rlim_max) {
    const rlim_t before = limit.rlim_cur;
    limit.rlim_cur = limit.rlim_max;
    if (::setrlimit(RLIMIT_NOFILE, &limit) == 0) {
      spdlog::info("descriptor limit raised from {} to {} (the hard limit)", before, limit.rlim_cur);
    } else {
      limit.rlim_cur = before;
    }
  }
  return limit.rlim_cur;
}

}  // namespace animspace::server
