// The serial driver: one Asio io_context on the driver thread, a read loop, and a backoff timer
// that reopens the device path after it disappears.
#include "drivers/serial_source.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/serial_port.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cstdint>
#include <string>

namespace gaitmon::drivers {

namespace asio = boost::asio;
using boost::system::error_code;

struct SerialSource::Impl {
  explicit Impl(SerialSettings s) : settings(std::move(s)) {}

  SerialSettings settings;
  asio::io_context io;
  asio::serial_port port{io};
  asio::steady_timer retry_timer{io};
  std::atomic<bool> stopping{false};
  std::chrono::milliseconds backoff{0};
  LinkState state = LinkState::Connecting;
  bool state_reported = false;
  std::string open_error;  ///< of the last failed attempt since the last connection
  // 4 KiB holds about 33 frames of the largest insole: one wake-up per ~0.17 s of data at
  // 100 Hz per foot, and far less than a pty's buffer.
  std::array<std::uint8_t, 4096> buffer{};
  const BytesHandler* on_bytes = nullptr;
  const StateHandler* on_state = nullptr;

  void report(LinkState next, const std::string& detail) {
    if (state_reported && next == state) return;
    state = next;
    state_reported = true;
    (*on_state)(next, detail);
  }

  error_code configure() {
    using base = asio::serial_port_base;
    error_code ec;
    port.set_option(base::baud_rate(settings.baud), ec);
    if (ec) return ec;
    port.set_option(base::character_size(static_cast<unsigned>(settings.data_bits)), ec);
    if (ec) return ec;
    const auto parity = settings.parity == SerialParity::Odd    ? base::parity::odd
                        : settings.parity == SerialParity::Even ? base::parity::even
                                                                : base::parity::none;
    port.set_option(base::parity(parity), ec);
    if (ec) return ec;
    port.set_option(
        base::stop_bits(settings.stop_bits == 2 ? base::stop_bits::two : base::stop_bits::one), ec);
    if (ec) return ec;
    const auto flow =
        settings.flow_control == SerialFlowControl::Software   ? base::flow_control::software
        : settings.flow_control == SerialFlowControl::Hardware ? base::flow_control::hardware
                                                               : base::flow_control::none;
    port.set_option(base::flow_control(flow), ec);
    return ec;
  }

  void try_open() {
    if (stopping.load()) return;
    report(LinkState::Connecting, settings.device);
    error_code ec;
    port.open(settings.device, ec);
    if (!ec) {
      ec = configure();
      if (ec) {
        error_code ignored;
        port.close(ignored);
      }
    }
    if (ec) {
      // A wrong path, permission or setting says why once, not at every attempt; a new reason
      // (the device appeared but is not ours to open) says it again.
      if (ec.message() != open_error) {
        open_error = ec.message();
        (*on_state)(LinkState::Connecting, settings.device + ": " + open_error);
      }
      schedule_retry();
      return;
    }
    open_error.clear();
    report(LinkState::Connected, settings.device);
    read();
  }

  void schedule_retry() {
    retry_timer.expires_after(backoff);
    backoff = std::min(backoff * 2, std::chrono::milliseconds(settings.reconnect_max_ms));
    retry_timer.async_wait([this](const error_code& ec) {
      if (!ec) try_open();
    });
  }

  void read() {
    port.async_read_some(asio::buffer(buffer), [this](const error_code& ec, std::size_t n) {
      if (n > 0) {
        // Data, not an open alone, shows the device works: one that fails its first read
        // keeps backing off.
        backoff = std::chrono::milliseconds(settings.reconnect_initial_ms);
        (*on_bytes)(std::span<const std::uint8_t>(buffer.data(), n));
      }
      if (stopping.load()) return;
      if (!ec) {
        read();
        return;
      }
      // End of file, EIO from a pty whose master closed, ENODEV from an unplugged adapter:
      // all mean the device is gone until the path opens again.
      error_code ignored;
      port.close(ignored);
      report(LinkState::Disconnected, settings.device + ": " + ec.message());
      schedule_retry();
    });
  }
};

SerialSource::SerialSource(SerialSettings settings)
    : impl_(std::make_unique<Impl>(std::move(settings))) {}

SerialSource::~SerialSource() = default;

void SerialSource::run(const BytesHandler& on_bytes, const StateHandler& on_state) {
  Impl& d = *impl_;
  if (d.stopping.load()) return;
  d.on_bytes = &on_bytes;
  d.on_state = &on_state;
  d.backoff = std::chrono::milliseconds(d.settings.reconnect_initial_ms);
  asio::post(d.io, [&d] { d.try_open(); });
  d.io.run();
  error_code ignored;
  d.port.close(ignored);
  if (d.state_reported && d.state != LinkState::Disconnected) {
    on_state(LinkState::Disconnected, d.settings.device + ": stopped");
  }
}

void SerialSource::stop() {
  impl_->stopping.store(true);
  impl_->io.stop();
}

}  // namespace gaitmon::drivers
