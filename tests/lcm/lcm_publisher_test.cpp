// LcmPublisher over memq://: every report arrives as its generated LCM type with every field
// equal, on its configured channel; failures are counted; concurrent publishing loses nothing.
#include "gaitmon/lcm_publisher.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <gaitmon/effects_t.hpp>
#include <gaitmon/fit_t.hpp>
#include <gaitmon/frame_t.hpp>
#include <gaitmon/raw_t.hpp>
#include <gaitmon/status_t.hpp>
#include <gaitmon/step_t.hpp>
#include <gaitmon/tissue_t.hpp>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "gaitmon/lcm_connection.hpp"
#include "lcm/sample_reports.hpp"
#include "log_capture.hpp"
#include "test_support.hpp"

namespace gaitmon {
namespace {

using ::testing::HasSubstr;

// Everything one memq:// bus delivered, by channel, as raw bytes.
struct Received {
  std::multimap<std::string, std::vector<std::uint8_t>> messages;
};

void record(const lcm::ReceiveBuffer* buffer, const std::string& channel, Received* received) {
  const auto* data = static_cast<const std::uint8_t*>(buffer->data);
  received->messages.emplace(channel, std::vector<std::uint8_t>(data, data + buffer->data_size));
}

// Drains the bus: memq:// delivers only inside handleTimeout on the same connection.
void drain(lcm::LCM& bus) {
  while (bus.handleTimeout(0) > 0) {
  }
}

template <typename Message>
Message only_message(const Received& received, const std::string& channel) {
  EXPECT_EQ(received.messages.count(channel), 1U) << channel;
  Message message;
  const auto it = received.messages.find(channel);
  if (it == received.messages.end()) return message;
  const auto& bytes = it->second;
  EXPECT_EQ(message.decode(bytes.data(), 0, static_cast<int>(bytes.size())),
            static_cast<int>(bytes.size()))
      << channel << " does not decode as " << Message::getTypeName();
  return message;
}

LcmSettings memq_settings() {
  LcmSettings settings;
  settings.url = "memq://";
  settings.raw_enabled = true;
  return settings;
}

class LcmPublisherMemq : public ::testing::Test {
 protected:
  std::shared_ptr<lcm::LCM> bus = open_lcm("memq://");
  Received received;
  void SetUp() override { bus->subscribeFunction(".*", &record, &received); }
};

TEST_F(LcmPublisherMemq, FrameReportArrivesAsFrameT) {
  LcmPublisher publisher(bus, memq_settings());
  publisher.publish(test::sample_frame());
  drain(*bus);
  const auto m = only_message<frame_t>(received, "GAITMON_FRAME");
  EXPECT_EQ(m.utime, 1763737200123456);
  EXPECT_EQ(m.foot, 1);
  EXPECT_EQ(m.frame, 4242);
  EXPECT_EQ(m.t_s, 42.42);
  for (int i = 0; i < 8; ++i) {
    SCOPED_TRACE(i);
    const auto& g = m.regions[i];
    EXPECT_EQ(g.force_n, 100.25 + i);
    EXPECT_EQ(g.active_area_mm2, 225.5 + i);
    EXPECT_EQ(g.ellipse_case, i % 6);
    EXPECT_EQ(g.centre_x_mm, -10.125 - i);
    EXPECT_EQ(g.centre_y_mm, 150.0625 + i);
    EXPECT_EQ(g.ra_mm, 20.5 + i);
    EXPECT_EQ(g.rb_mm, 10.75 + i);
    EXPECT_EQ(g.angle_rad, 0.3 + 0.01 * i);
    EXPECT_EQ(g.ellipse_area_mm2, 700.125 + i);
  }
  EXPECT_EQ(received.messages.size(), 1U);
  EXPECT_EQ(publisher.published(), 1U);
  EXPECT_EQ(publisher.failed_publishes(), 0U);
}

TEST_F(LcmPublisherMemq, StepEventArrivesAsStepT) {
  LcmPublisher publisher(bus, memq_settings());
  publisher.publish(test::sample_step());
  StepEvent heel = test::sample_step();
  heel.kind = StepEvent::Kind::HeelStrike;
  heel.complete = true;
  heel.foot = Foot::Right;
  drain(*bus);
  const auto m = only_message<step_t>(received, "GAITMON_STEP");
  EXPECT_EQ(m.utime, 1763737200223456);
  EXPECT_EQ(m.foot, 0);
  EXPECT_EQ(m.step, 17);
  EXPECT_EQ(m.kind, 1);  // toe off
  EXPECT_FALSE(m.complete);
  EXPECT_EQ(m.frame, 1234);
  EXPECT_EQ(m.t_s, 12.34);

  received.messages.clear();
  publisher.publish(heel);
  drain(*bus);
  const auto h = only_message<step_t>(received, "GAITMON_STEP");
  EXPECT_EQ(h.kind, 0);  // heel strike
  EXPECT_TRUE(h.complete);
  EXPECT_EQ(h.foot, 1);
}

TEST_F(LcmPublisherMemq, FitReportArrivesAsFitT) {
  LcmPublisher publisher(bus, memq_settings());
  publisher.publish(test::sample_fit());
  drain(*bus);
  const auto m = only_message<fit_t>(received, "GAITMON_FIT");
  EXPECT_EQ(m.utime, 1763737200323456);
  EXPECT_EQ(m.foot, 1);
  EXPECT_EQ(m.step, 23);
  EXPECT_EQ(m.t_heel_strike_s, 30.125);
  EXPECT_EQ(m.t_toe_off_s, 30.75);
  EXPECT_EQ(m.nrmse_total_pct, 4.5);
  EXPECT_EQ(m.latency_ms, 1.875);
  EXPECT_EQ(m.effects_inside, "stress_relaxation,hysteresis");
  EXPECT_EQ(m.effects_utime, 1763737199000000);
  const char* const names[] = {
      "heel",   "midfoot_posterior", "midfoot_anterior", "met1_2", "met3_5", "toe1", "toe2",
      "toes3_5"};
  for (int i = 0; i < 8; ++i) {
    SCOPED_TRACE(i);
    const auto& g = m.regions[i];
    EXPECT_EQ(g.region, i);
    EXPECT_EQ(g.region_name, names[i]);
    EXPECT_EQ(g.status, i == 6 ? "fit_failed:no convergence" : (i == 7 ? "no_contact" : "ok"));
    EXPECT_EQ(g.kbar_n_per_mm3, 0.117 + 0.001 * i);
    EXPECT_EQ(g.n, 0.5 + 0.01 * i);
    EXPECT_EQ(g.cbar_ns_per_mm3, 0.02 + 0.001 * i);
    EXPECT_EQ(g.m, 1.1 + 0.01 * i);
    EXPECT_EQ(g.se_kbar, 0.003 + 0.0001 * i);
    EXPECT_EQ(g.se_n, 0.02 + 0.001 * i);
    EXPECT_EQ(g.se_cbar, 0.002 + 0.0001 * i);
    EXPECT_EQ(g.se_m, 0.05 + 0.001 * i);
    EXPECT_EQ(g.se_kbar_total, 0.005 + 0.0001 * i);
    EXPECT_EQ(g.se_n_total, 0.03 + 0.001 * i);
    EXPECT_EQ(g.se_cbar_total, 0.004 + 0.0001 * i);
    EXPECT_EQ(g.se_m_total, 0.0625 + 0.001 * i);
    EXPECT_EQ(g.A_mm, 40.5 + i);
    EXPECT_EQ(g.B_mm, 30.25 + i);
    EXPECT_EQ(g.C_mm, 60.125 + i);
    EXPECT_EQ(g.d0_mm, 10.5 + i);
    EXPECT_EQ(g.nrmse_pct, 3.25 + i);
    EXPECT_EQ(g.m_steps, i < 3 ? 40 + i : 0);
  }
}

TEST_F(LcmPublisherMemq, StatusReportArrivesAsStatusT) {
  LcmPublisher publisher(bus, memq_settings());
  publisher.publish(test::sample_status());
  drain(*bus);
  const auto m = only_message<status_t>(received, "GAITMON_STATUS");
  EXPECT_EQ(m.utime, 1763737200423456);
  EXPECT_EQ(m.connection, "connected");
  EXPECT_EQ(m.bytes_received, 123456789);
  EXPECT_EQ(m.frames_decoded, 98765);
  EXPECT_EQ(m.crc_errors, 3);
  EXPECT_EQ(m.resyncs, 5);
  EXPECT_EQ(m.frames_truncated, 37);
  EXPECT_EQ(m.header_errors, 41);
  EXPECT_EQ(m.sequence_restarts, 43);
  EXPECT_EQ(m.segmentation_gaps, 47);
  EXPECT_EQ(m.frames_lost_sequence, 7);
  EXPECT_EQ(m.reconnects, 2);
  EXPECT_EQ(m.transfers_overflowed, 53);
  EXPECT_EQ(m.ring_depth, 11);
  EXPECT_EQ(m.ring_drops, 13);
  EXPECT_EQ(m.frames_processed, 98700);
  EXPECT_EQ(m.frames_rejected, 31);
  EXPECT_EQ(m.steps_detected, 17);
  EXPECT_EQ(m.step_backlog, 19);
  EXPECT_EQ(m.step_drops, 23);
  EXPECT_EQ(m.fits_published, 29);
  EXPECT_EQ(m.fits_failed, 31);
  EXPECT_EQ(m.fit_latency_p50_ms, 1.5);
  EXPECT_EQ(m.fit_latency_p99_ms, 12.25);
}

TEST_F(LcmPublisherMemq, RawFrameReportArrivesAsRawTWhenEnabled) {
  LcmPublisher publisher(bus, memq_settings());
  publisher.publish(test::sample_raw());
  drain(*bus);
  const auto m = only_message<raw_t>(received, "GAITMON_RAW");
  EXPECT_EQ(m.utime, 1763737200523456);
  EXPECT_EQ(m.foot, 0);
  EXPECT_EQ(m.sequence, 4000000000);
  EXPECT_EQ(m.device_time_us, 3999999999);
  ASSERT_EQ(m.num_bits, 161);
  ASSERT_EQ(m.bits.size(), 161U);
  for (int i = 0; i < 161; ++i) EXPECT_EQ(m.bits[i], (i * 37) % 256) << i;
}

TEST_F(LcmPublisherMemq, EffectsReportArrivesAsEffectsT) {
  LcmPublisher publisher(bus, memq_settings());
  publisher.publish(test::sample_effects());
  drain(*bus);
  const auto m = only_message<effects_t>(received, "GAITMON_EFFECTS");
  EXPECT_EQ(m.utime, 1763737200623456);
  EXPECT_TRUE(m.final_estimate);
  EXPECT_EQ(m.steps, 97);
  EXPECT_EQ(m.t_first_heel_strike_s, 11.25);
  EXPECT_EQ(m.t_last_toe_off_s, 63.5);
  EXPECT_EQ(m.baseline_nrmse_pct, 6.75);
  EXPECT_EQ(m.extended_nrmse_pct, 6.375);
  EXPECT_EQ(m.baseline_heldout_nrmse_pct, 6.8125);
  EXPECT_EQ(m.extended_heldout_nrmse_pct, 6.4375);
  ASSERT_EQ(m.num_params, 3);
  ASSERT_EQ(m.params.size(), 3U);
  EXPECT_EQ(m.params[0].effect, "stress_relaxation");
  EXPECT_EQ(m.params[0].name, "strength");
  EXPECT_EQ(m.params[0].value, 0.3325);
  EXPECT_EQ(m.params[0].se, 0.0094);
  EXPECT_EQ(m.params[1].name, "tau_s");
  EXPECT_EQ(m.params[1].value, 0.228125);
  EXPECT_EQ(m.params[2].effect, "impact_transient");
  EXPECT_EQ(m.params[2].name, "amplitude_n");
  EXPECT_EQ(m.params[2].value, 81.5);
  EXPECT_EQ(m.params[2].se, 4.25);
}

TEST_F(LcmPublisherMemq, TissueReportArrivesAsTissueT) {
  LcmPublisher publisher(bus, memq_settings());
  publisher.publish(test::sample_tissue());
  drain(*bus);
  const auto m = only_message<tissue_t>(received, "GAITMON_TISSUE");
  EXPECT_EQ(m.utime, 1763737200723456);
  EXPECT_FALSE(m.final_estimate);
  EXPECT_EQ(m.foot, tissue_t::LEFT);
  EXPECT_EQ(m.step, 41);
  EXPECT_EQ(m.t_first_heel_strike_s, 2.5);
  EXPECT_EQ(m.t_last_toe_off_s, 95.25);
  for (int i = 0; i < 8; ++i) {
    SCOPED_TRACE(i);
    const region_tissue_t& g = m.regions[i];
    EXPECT_EQ(g.region, i);
    EXPECT_EQ(g.steps, 80 - i);
    EXPECT_EQ(g.kbar_n_per_mm3, 0.125 + 0.001 * i);
    EXPECT_EQ(g.se_m, 0.061 + 0.001 * i);
  }
  EXPECT_EQ(m.regions[0].region_name, "heel");
  EXPECT_EQ(m.regions[0].status, "ok");
  EXPECT_EQ(m.regions[7].region_name, "toes3_5");
  EXPECT_EQ(m.regions[7].status, "not_pooled:the pooled mean leaves the fit bounds");
  EXPECT_EQ(m.regions[3].n, 0.375 + 0.03);
  EXPECT_EQ(m.regions[3].cbar_ns_per_mm3, 0.015625 + 0.003);
  EXPECT_EQ(m.regions[3].m, 1.0625 + 0.03);
  EXPECT_EQ(m.regions[3].se_kbar, 0.0046 + 0.0003);
  EXPECT_EQ(m.regions[3].se_n, 0.021 + 0.003);
  EXPECT_EQ(m.regions[3].se_cbar, 0.0013 + 0.0003);
}

TEST_F(LcmPublisherMemq, RawFramesAreNotPublishedByDefault) {
  LcmSettings settings;
  settings.url = "memq://";
  ASSERT_FALSE(settings.raw_enabled);
  LcmPublisher publisher(bus, settings);
  publisher.publish(test::sample_raw());
  publisher.publish(test::sample_step());
  drain(*bus);
  EXPECT_EQ(received.messages.count("GAITMON_RAW"), 0U);
  EXPECT_EQ(received.messages.count("GAITMON_STEP"), 1U);
  EXPECT_EQ(publisher.published(), 1U);
}

TEST_F(LcmPublisherMemq, UsesTheConfiguredChannels) {
  LcmSettings settings = memq_settings();
  settings.channels = {"A.FRAME", "A_STEP", "A_FIT", "A_STATUS", "A_RAW", "A_EFFECTS", "A_TISSUE"};
  LcmPublisher publisher(bus, settings);
  test::publish_samples(publisher);
  drain(*bus);
  std::multiset<std::string> channels;
  for (const auto& [channel, bytes] : received.messages) channels.insert(channel);
  EXPECT_EQ(channels, (std::multiset<std::string>{"A.FRAME", "A_STEP", "A_FIT", "A_STATUS", "A_RAW",
                                                  "A_EFFECTS", "A_TISSUE"}));
  // Each channel carries its own type: decoding as another type fails on the fingerprint.
  EXPECT_EQ(only_message<fit_t>(received, "A_FIT").step, 23);
  const auto& frame_bytes = received.messages.find("A.FRAME")->second;
  step_t wrong;
  EXPECT_LT(wrong.decode(frame_bytes.data(), 0, static_cast<int>(frame_bytes.size())), 0);
}

TEST(LcmPublisher, RefusesABadUrlAtConstruction) {
  for (const char* url : {"nosuch://", "udpm://239.255.76.67:notaport", "memq"}) {
    LcmSettings settings;
    settings.url = url;
    try {
      LcmPublisher publisher(settings);
      ADD_FAILURE() << url << ": no LcmError";
    } catch (const LcmError& e) {
      EXPECT_THAT(e.what(), HasSubstr(url));
    }
  }
}

// A file:// bus opened for reading refuses every publish: the publisher counts, logs (at most
// once a second) and carries on.
TEST(LcmPublisher, CountsAndLogsFailedPublishesWithoutThrowing) {
  const auto log = test::scratch_dir("lcm-failed") / "one.log";
  LcmSettings settings;
  settings.url = "file://" + log.string() + "?mode=w";
  {
    LcmPublisher writer(settings);  // LCM opens a log for reading only if it holds an event
    writer.publish(test::sample_step());
    ASSERT_EQ(writer.published(), 1U);
  }
  settings.url = "file://" + log.string() + "?mode=r";
  LcmPublisher publisher(settings);
  std::string logged;
  {
    const test::LogCapture capture;
    EXPECT_NO_THROW(publisher.publish(test::sample_status()));
    EXPECT_NO_THROW(publisher.publish(test::sample_fit()));
    logged = capture.text.str();
  }
  EXPECT_EQ(publisher.failed_publishes(), 2U);
  EXPECT_EQ(publisher.published(), 0U);
  EXPECT_NE(logged.find("LCM: a message on GAITMON_STATUS was lost: LCM did not send it; 1 lost so "
                        "far"),
            std::string::npos)
      << logged;
  EXPECT_EQ(logged.find("GAITMON_FIT"), std::string::npos) << "not throttled: " << logged;
}

// Several threads publish at once (the detector, the fit workers, the status timer): every
// message arrives whole. Run under TSan in CI.
TEST_F(LcmPublisherMemq, ConcurrentPublishersLoseAndMixNothing) {
  constexpr int kThreads = 4;
  constexpr int kPerThread = 300;
  LcmPublisher publisher(bus, memq_settings());
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&publisher, t] {
      for (int i = 0; i < kPerThread; ++i) {
        FrameReport frame = test::sample_frame();
        frame.frame = t * 100000 + i;
        frame.regions[7].force_n = t * 100000 + i;
        publisher.publish(frame);
        FitReport fit = test::sample_fit();
        fit.step = t * 100000 + i;
        fit.regions[0].status = "ok thread " + std::to_string(t);
        publisher.publish(fit);
      }
    });
  }
  for (auto& thread : threads) thread.join();
  drain(*bus);
  EXPECT_EQ(publisher.published(), 2U * kThreads * kPerThread);
  EXPECT_EQ(publisher.failed_publishes(), 0U);
  std::set<std::int64_t> frames;
  std::set<std::int32_t> steps;
  for (const auto& [channel, bytes] : received.messages) {
    if (channel == "GAITMON_FRAME") {
      frame_t m;
      ASSERT_GT(m.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
      EXPECT_EQ(m.regions[7].force_n, static_cast<double>(m.frame));
      EXPECT_EQ(m.regions[0].force_n, 100.25);
      frames.insert(m.frame);
    } else {
      ASSERT_EQ(channel, "GAITMON_FIT");
      fit_t m;
      ASSERT_GT(m.decode(bytes.data(), 0, static_cast<int>(bytes.size())), 0);
      EXPECT_EQ(m.regions[0].status, "ok thread " + std::to_string(m.step / 100000));
      steps.insert(m.step);
    }
  }
  EXPECT_EQ(frames.size(), static_cast<std::size_t>(kThreads * kPerThread));
  EXPECT_EQ(steps.size(), static_cast<std::size_t>(kThreads * kPerThread));
}

}  // namespace
}  // namespace gaitmon
