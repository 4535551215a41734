// Who already listens on a TCP port, for the message a daemon prints when it cannot bind.
//
// gRPC and cpp-httplib both set SO_REUSEPORT by default, which lets a second daemon bind a busy
// address and receive a random share of the connections (issue #21: `animspace list` answered
// from one repository or the other). The daemon turns that off; when its bind then fails, this
// names the process in the way, read from Linux's /proc (the socket's inode in /proc/net/tcp{,6},
// then the process holding that inode among /proc/<pid>/fd).
#pragma once

#include <optional>
#include <string>

namespace animspace::server {

// "pid 1234 (animspaced --listen 127.0.0.1:50051)" for the process listening on `port`; "a process
// this user cannot inspect" when a listening socket exists but its owner is not visible; nullopt
// when nothing listens on the port (or /proc is unavailable).
std::optional<std::string> describe_tcp_listener(int port);

// The port of a "host:port" or "[v6]:port" address; nullopt when it has none.
std::optional<int> port_of_address(const std::string& address);

}  // namespace animspace::server
