// LcmSubscriber over memq://: each report comes back as the struct that was published, on the
// channels asked for; foreign or malformed messages are counted, not delivered.
#include "gaitmon/lcm_subscriber.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <gaitmon/frame_t.hpp>
#include <gaitmon/raw_t.hpp>
#include <gaitmon/step_t.hpp>
#include <gaitmon/tissue_t.hpp>
#include <lcm/lcm-cpp.hpp>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "gaitmon/lcm_connection.hpp"
#include "gaitmon/lcm_publisher.hpp"
#include "lcm/sample_reports.hpp"
#include "log_capture.hpp"

namespace gaitmon {
namespace {

using ::testing::HasSubstr;

struct Delivery {
  std::string channel;
  LcmMessage message;
};

class LcmSubscriberMemq : public ::testing::Test {
 protected:
  LcmSubscriberMemq() {
    settings.url = "memq://";
    settings.raw_enabled = true;
  }

  std::vector<Delivery> deliveries;
  LcmSubscriber::Handler record() {
    return [this](const std::string& channel, const LcmMessage& message) {
      deliveries.push_back({channel, message});
    };
  }
  static void drain(LcmSubscriber& subscriber) {
    while (subscriber.handle(0)) {
    }
  }

  std::shared_ptr<lcm::LCM> bus = open_lcm("memq://");
  LcmSettings settings;
};

void expect_same(const FrameReport& a, const FrameReport& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.foot, b.foot);
  EXPECT_EQ(a.frame, b.frame);
  EXPECT_EQ(a.t_s, b.t_s);
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    SCOPED_TRACE(i);
    const auto& x = a.regions[i];
    const auto& y = b.regions[i];
    EXPECT_EQ(x.force_n, y.force_n);
    EXPECT_EQ(x.active_area_mm2, y.active_area_mm2);
    EXPECT_EQ(x.ellipse_case, y.ellipse_case);
    EXPECT_EQ(x.centre_x_mm, y.centre_x_mm);
    EXPECT_EQ(x.centre_y_mm, y.centre_y_mm);
    EXPECT_EQ(x.ra_mm, y.ra_mm);
    EXPECT_EQ(x.rb_mm, y.rb_mm);
    EXPECT_EQ(x.angle_rad, y.angle_rad);
    EXPECT_EQ(x.ellipse_area_mm2, y.ellipse_area_mm2);
  }
}

void expect_same(const StepEvent& a, const StepEvent& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.foot, b.foot);
  EXPECT_EQ(a.step, b.step);
  EXPECT_EQ(a.kind, b.kind);
  EXPECT_EQ(a.complete, b.complete);
  EXPECT_EQ(a.frame, b.frame);
  EXPECT_EQ(a.t_s, b.t_s);
}

// A region's status, four tissue parameters and their standard errors, in its fit and its pool.
template <typename RegionReport>
void expect_same_region(const RegionReport& x, const RegionReport& y) {
  EXPECT_EQ(x.region, y.region);
  EXPECT_EQ(x.status, y.status);
  EXPECT_EQ(x.kbar_n_per_mm3, y.kbar_n_per_mm3);
  EXPECT_EQ(x.n, y.n);
  EXPECT_EQ(x.cbar_ns_per_mm3, y.cbar_ns_per_mm3);
  EXPECT_EQ(x.m, y.m);
  EXPECT_EQ(x.se_kbar, y.se_kbar);
  EXPECT_EQ(x.se_n, y.se_n);
  EXPECT_EQ(x.se_cbar, y.se_cbar);
  EXPECT_EQ(x.se_m, y.se_m);
}

void expect_same(const FitReport& a, const FitReport& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.foot, b.foot);
  EXPECT_EQ(a.step, b.step);
  EXPECT_EQ(a.t_heel_strike_s, b.t_heel_strike_s);
  EXPECT_EQ(a.t_toe_off_s, b.t_toe_off_s);
  EXPECT_EQ(a.nrmse_total_pct, b.nrmse_total_pct);
  EXPECT_EQ(a.latency_ms, b.latency_ms);
  EXPECT_EQ(a.effects_inside, b.effects_inside);
  EXPECT_EQ(a.effects_utime, b.effects_utime);
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    SCOPED_TRACE(i);
    const auto& x = a.regions[i];
    const auto& y = b.regions[i];
    expect_same_region(x, y);
    EXPECT_EQ(x.se_kbar_total, y.se_kbar_total);
    EXPECT_EQ(x.se_n_total, y.se_n_total);
    EXPECT_EQ(x.se_cbar_total, y.se_cbar_total);
    EXPECT_EQ(x.se_m_total, y.se_m_total);
    EXPECT_EQ(x.A_mm, y.A_mm);
    EXPECT_EQ(x.B_mm, y.B_mm);
    EXPECT_EQ(x.C_mm, y.C_mm);
    EXPECT_EQ(x.d0_mm, y.d0_mm);
    EXPECT_EQ(x.nrmse_pct, y.nrmse_pct);
    EXPECT_EQ(x.m_steps, y.m_steps);
  }
}

void expect_same(const StatusReport& a, const StatusReport& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.connection, b.connection);
  EXPECT_EQ(a.bytes_received, b.bytes_received);
  EXPECT_EQ(a.frames_decoded, b.frames_decoded);
  EXPECT_EQ(a.crc_errors, b.crc_errors);
  EXPECT_EQ(a.resyncs, b.resyncs);
  EXPECT_EQ(a.frames_truncated, b.frames_truncated);
  EXPECT_EQ(a.header_errors, b.header_errors);
  EXPECT_EQ(a.sequence_restarts, b.sequence_restarts);
  EXPECT_EQ(a.segmentation_gaps, b.segmentation_gaps);
  EXPECT_EQ(a.frames_lost_sequence, b.frames_lost_sequence);
  EXPECT_EQ(a.reconnects, b.reconnects);
  EXPECT_EQ(a.transfers_overflowed, b.transfers_overflowed);
  EXPECT_EQ(a.ring_depth, b.ring_depth);
  EXPECT_EQ(a.ring_drops, b.ring_drops);
  EXPECT_EQ(a.frames_processed, b.frames_processed);
  EXPECT_EQ(a.frames_rejected, b.frames_rejected);
  EXPECT_EQ(a.steps_detected, b.steps_detected);
  EXPECT_EQ(a.step_backlog, b.step_backlog);
  EXPECT_EQ(a.step_drops, b.step_drops);
  EXPECT_EQ(a.fits_published, b.fits_published);
  EXPECT_EQ(a.fits_failed, b.fits_failed);
  EXPECT_EQ(a.fit_latency_p50_ms, b.fit_latency_p50_ms);
  EXPECT_EQ(a.fit_latency_p99_ms, b.fit_latency_p99_ms);
}

void expect_same(const RawFrameReport& a, const RawFrameReport& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.foot, b.foot);
  EXPECT_EQ(a.sequence, b.sequence);
  EXPECT_EQ(a.device_time_us, b.device_time_us);
  EXPECT_EQ(a.bits, b.bits);
}

void expect_same(const EffectsReport& a, const EffectsReport& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.final_estimate, b.final_estimate);
  EXPECT_EQ(a.steps, b.steps);
  EXPECT_EQ(a.t_first_heel_strike_s, b.t_first_heel_strike_s);
  EXPECT_EQ(a.t_last_toe_off_s, b.t_last_toe_off_s);
  EXPECT_EQ(a.baseline_nrmse_pct, b.baseline_nrmse_pct);
  EXPECT_EQ(a.extended_nrmse_pct, b.extended_nrmse_pct);
  EXPECT_EQ(a.baseline_heldout_nrmse_pct, b.baseline_heldout_nrmse_pct);
  EXPECT_EQ(a.extended_heldout_nrmse_pct, b.extended_heldout_nrmse_pct);
  ASSERT_EQ(a.params.size(), b.params.size());
  for (std::size_t i = 0; i < a.params.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(a.params[i].effect, b.params[i].effect);
    EXPECT_EQ(a.params[i].name, b.params[i].name);
    EXPECT_EQ(a.params[i].value, b.params[i].value);
    EXPECT_EQ(a.params[i].se, b.params[i].se);
  }
}

void expect_same(const TissueReport& a, const TissueReport& b) {
  EXPECT_EQ(a.utime, b.utime);
  EXPECT_EQ(a.final_estimate, b.final_estimate);
  EXPECT_EQ(a.foot, b.foot);
  EXPECT_EQ(a.step, b.step);
  EXPECT_EQ(a.t_first_heel_strike_s, b.t_first_heel_strike_s);
  EXPECT_EQ(a.t_last_toe_off_s, b.t_last_toe_off_s);
  for (std::size_t i = 0; i < kRegionCount; ++i) {
    SCOPED_TRACE(i);
    expect_same_region(a.regions[i], b.regions[i]);
    EXPECT_EQ(a.regions[i].steps, b.regions[i].steps);
  }
}

template <typename Report>
void expect_delivered(const Delivery& d, const std::string& channel, const Report& sent) {
  EXPECT_EQ(d.channel, channel);
  const Report* got = std::get_if<Report>(&d.message);
  ASSERT_NE(got, nullptr) << channel << " delivered the wrong alternative";
  expect_same(*got, sent);
}

TEST_F(LcmSubscriberMemq, EveryReportComesBackAsPublished) {
  LcmSubscriber subscriber(bus, settings, {}, record());
  LcmPublisher publisher(bus, settings);
  test::publish_samples(publisher);
  drain(subscriber);
  ASSERT_EQ(deliveries.size(), 7U);
  expect_delivered(deliveries[0], "GAITMON_FRAME", test::sample_frame());
  expect_delivered(deliveries[1], "GAITMON_STEP", test::sample_step());
  expect_delivered(deliveries[2], "GAITMON_FIT", test::sample_fit());
  expect_delivered(deliveries[3], "GAITMON_STATUS", test::sample_status());
  expect_delivered(deliveries[4], "GAITMON_RAW", test::sample_raw());
  expect_delivered(deliveries[5], "GAITMON_EFFECTS", test::sample_effects());
  expect_delivered(deliveries[6], "GAITMON_TISSUE", test::sample_tissue());
  EXPECT_EQ(subscriber.decode_errors(), 0U);
}

TEST_F(LcmSubscriberMemq, OnlyTheChannelsAskedForAreDelivered) {
  settings.channels.fit = "LAB.FIT";
  LcmSubscriber subscriber(bus, settings, {"LAB.FIT", "GAITMON_STEP"}, record());
  LcmPublisher publisher(bus, settings);
  publisher.publish(test::sample_frame());
  publisher.publish(test::sample_fit());
  publisher.publish(test::sample_status());
  publisher.publish(test::sample_step());
  // "." is literal: LABXFIT is another channel.
  LcmSettings other = settings;
  other.channels.fit = "LABXFIT";
  LcmPublisher(bus, other).publish(test::sample_fit());
  drain(subscriber);
  ASSERT_EQ(deliveries.size(), 2U);
  expect_delivered(deliveries[0], "LAB.FIT", test::sample_fit());
  expect_delivered(deliveries[1], "GAITMON_STEP", test::sample_step());
}

TEST_F(LcmSubscriberMemq, ForeignAndImpossibleMessagesAreCountedNotDelivered) {
  LcmSubscriber subscriber(bus, settings, {}, record());
  // A step_t on the fit channel: the fingerprint differs.
  step_t step;
  step.foot = 0;
  bus->publish("GAITMON_FIT", &step);
  // A step_t with a foot that is neither 0 nor 1.
  step.foot = 2;
  bus->publish("GAITMON_STEP", &step);
  // Bytes that are no message at all.
  const char junk[] = "junk";
  bus->publish("GAITMON_STATUS", junk, sizeof junk);
  // A frame_t with an ellipse case past the last one (long, 5).
  frame_t frame;
  frame.foot = 0;
  frame.regions[3].ellipse_case = 6;
  bus->publish("GAITMON_FRAME", &frame);
  // A tissue_t with a negative step count.
  tissue_t tissue;
  tissue.foot = 1;
  for (std::int8_t i = 0; i < 8; ++i) tissue.regions[i].region = i;
  tissue.regions[2].steps = -1;
  bus->publish("GAITMON_TISSUE", &tissue);
  const test::LogCapture log;
  drain(subscriber);
  EXPECT_TRUE(deliveries.empty());
  EXPECT_EQ(subscriber.decode_errors(), 5U);
  // Logged too, the first of them (the others come within the same second).
  EXPECT_NE(
      log.text.str().find("LCM: a malformed message on GAITMON_FIT skipped: another type, cut "
                          "short or an impossible value; 1 so far (0 similar suppressed)"),
      std::string::npos)
      << log.text.str();
}

// The generated decoder throws for a negative array length; the exception must not cross LCM's
// C callback, and the next message still arrives.
TEST_F(LcmSubscriberMemq, AMessageTheDecoderThrowsOnIsCountedAndSkipped) {
  LcmSubscriber subscriber(bus, settings, {}, record());
  raw_t raw;
  raw.foot = 0;
  raw.num_bits = 0;
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(raw.getEncodedSize()));
  ASSERT_EQ(raw.encode(bytes.data(), 0, static_cast<int>(bytes.size())),
            static_cast<int>(bytes.size()));
  // num_bits (big-endian int32) follows the hash, utime, foot, sequence and device_time_us.
  const std::size_t num_bits_at = 8 + 8 + 1 + 8 + 8;
  ASSERT_EQ(bytes.size(), num_bits_at + 4);
  for (std::size_t i = 0; i < 4; ++i) bytes[num_bits_at + i] = 0xFF;
  bus->publish(settings.channels.raw, bytes.data(), static_cast<unsigned>(bytes.size()));
  LcmPublisher(bus, settings).publish(test::sample_step());
  drain(subscriber);
  EXPECT_EQ(subscriber.decode_errors(), 1U);
  ASSERT_EQ(deliveries.size(), 1U);
  expect_delivered(deliveries[0], settings.channels.step, test::sample_step());
}

TEST_F(LcmSubscriberMemq, AHandlersExceptionIsRethrownByHandle) {
  LcmSubscriber subscriber(bus, settings, {}, [](const std::string&, const LcmMessage&) {
    throw std::runtime_error("handler failed");
  });
  LcmPublisher(bus, settings).publish(test::sample_step());
  try {
    subscriber.handle(0);
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "handler failed");
  }
}

TEST_F(LcmSubscriberMemq, RefusesAChannelTheSettingsDoNotName) {
  try {
    LcmSubscriber subscriber(bus, settings, {"GAITMON_FITS"}, record());
    FAIL() << "no LcmError";
  } catch (const LcmError& e) {
    EXPECT_THAT(e.what(), HasSubstr("\"GAITMON_FITS\" is not a gaitmon channel"));
  }
}

TEST(LcmSubscriber, RefusesABadUrl) {
  LcmSettings settings;
  settings.url = "udpm://239.255.76.67:notaport";
  EXPECT_THROW(LcmSubscriber(settings, {}, [](const std::string&, const LcmMessage&) {}), LcmError);
}

}  // namespace
}  // namespace gaitmon
