// Runs the real animspaced binary (or another server started the same way: the transport floor) as
// a child process and waits until it listens: the integration tests and animspace-bench's serving
// suites both drive the daemon from the outside, through the protocol, so neither may carry its
// own copy of the launcher.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

namespace animspace::harness {

class DaemonProcess {
 public:
  // Starts `animspaced --port-file … --listen 127.0.0.1:0 <extra_args>` (no --listen of its own
  // when extra_args has one) with stdout/stderr
  // going to `log_path`, and waits until it has written its port. Throws std::runtime_error
  // (failing the test, ending the bench) when it does not come up within `timeout`.
  DaemonProcess(const std::vector<std::string>& extra_args, const std::filesystem::path& work_dir,
                std::chrono::milliseconds timeout = std::chrono::seconds(90));
  // The same for another server binary that takes --port-file and --listen as animspaced does
  // (the transport floor). The log and port file are named after the binary (<name>.log).
  DaemonProcess(const std::filesystem::path& binary, const std::vector<std::string>& extra_args,
                const std::filesystem::path& work_dir, std::chrono::milliseconds timeout = std::chrono::seconds(90));
  // Kills the process if it is still running.
  ~DaemonProcess();
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;

  int port() const { return port_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  pid_t pid() const { return pid_; }
  const std::filesystem::path& log_path() const { return log_path_; }
  std::string log() const;

  void send_signal(int signal_number) const;
  // Waits for the process to exit; returns its exit status (or 128 + signal), or -1 on timeout.
  int wait_for_exit(std::chrono::milliseconds timeout);

 private:
  pid_t pid_ = -1;
  int port_ = 0;
  std::filesystem::path log_path_;
};

// Path of the animspaced binary to run: $ANIMSPACED, else the one beside the running program
// (harness/build_tree.h).
std::filesystem::path daemon_binary();

// Path of animspace-transport-floor (server/transport_floor/): $ANIMSPACE_TRANSPORT_FLOOR, else the
// one beside the running program.
std::filesystem::path transport_floor_binary();

}  // namespace animspace::harness
