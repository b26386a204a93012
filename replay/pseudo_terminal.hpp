// The fake insole's serial port: a pseudo-terminal in raw mode, which a reader opens as it would
// a USB-serial adapter, and the symlink that stands for the adapter's stable by-id name.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace gaitmon::replay {

/// A pseudo-terminal in raw mode, so bytes pass unchanged. This end keeps the reader's side open
/// too: bytes written before a reader opens it wait in the pty, and unread() sees the reader
/// drain them. Destroying it is an unplug: the reader is hung up, so a read in progress fails
/// with EIO and later reads find end of file.
class PseudoTerminal {
 public:
  /// Throws std::system_error naming the call that failed.
  PseudoTerminal();
  ~PseudoTerminal();
  PseudoTerminal(const PseudoTerminal&) = delete;
  PseudoTerminal& operator=(const PseudoTerminal&) = delete;

  /// The device's end, written to.
  int fd() const { return master_; }
  /// The reader's end, such as /dev/pts/3.
  const std::string& path() const { return path_; }
  /// Bytes written and not yet taken by a reader.
  int unread() const;
  /// Waits until a reader has taken every byte written, at most `limit` or until *stop is set.
  /// Bytes pass a flip buffer before they count as unread, so it takes three empty checks in a
  /// row, 20 ms apart. Returns the bytes left.
  int wait_drained(std::chrono::milliseconds limit, const std::atomic<bool>* stop = nullptr) const;

 private:
  int master_ = -1;
  int slave_ = -1;
  std::string path_;
};

/// Writes every byte to `fd`, through partial writes. An interrupted write, or one that finds no
/// room on a non-blocking fd (a pty nobody reads), is retried after at most 100 ms, unless *stop
/// is set: then it returns false. Throws std::system_error on any other failure.
bool write_all(int fd, std::span<const std::uint8_t> bytes,
               const std::atomic<bool>* stop = nullptr);

/// Points `link` at `target` by renaming a new symlink over it, so that a reader never finds
/// the link missing or half-written.
void point_link(const std::filesystem::path& link, const std::string& target);

}  // namespace gaitmon::replay
