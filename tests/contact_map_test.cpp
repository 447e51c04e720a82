// The contact map (SimulatorOptions::contact_map, src/physics/contact_map.hpp): the fast path
// must give the reference answers. A long Hunt-Crossley sequence simulated with the map agrees
// with the same sequence integrated 1000 times tighter at least as well as the contact-by-
// contact integration at the simulation's own tolerance does; a panel whose check fails is
// refused and its speeds integrated; the map is built only where it pays.
#include "physics/contact_map.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {
namespace {

Scene LawScene(const std::string& law) {
  Scene s;  // the default scene: 1 cm steel ball from 0.2 m
  s.law.name = law;
  return s;
}

Simulation RunWith(const Scene& s, bool map, double rtol) {
  const auto law = CreateLaw(s.law, s);
  SimulatorOptions o;
  o.contact_map = map;
  o.rel_tolerance = rtol;
  return Simulate(s, *law, law->ParameterValues(), o);
}

struct Errors {
  double v_in = 0.0, e = 0.0, time_s = 0.0;
};

// The largest relative errors of a run's impact speeds and restitutions, and the largest
// absolute error of its impact times, against the reference run (impact by impact).
Errors Against(const Simulation& a, const Simulation& ref) {
  Errors out;
  const size_t n = std::min(a.impacts.size(), ref.impacts.size());
  for (size_t i = 0; i + 1 < n; ++i) {  // the last impact's contact may end stuck
    const SimImpact& x = a.impacts[i];
    const SimImpact& y = ref.impacts[i];
    out.v_in = std::max(out.v_in, std::abs(x.v_in_m_s - y.v_in_m_s) / y.v_in_m_s);
    out.e = std::max(out.e, std::abs(x.v_out_m_s / x.v_in_m_s - y.v_out_m_s / y.v_in_m_s));
    out.time_s = std::max(out.time_s, std::abs(x.time_s - y.time_s));
  }
  return out;
}

class LongSequence : public ::testing::TestWithParam<const char*> {};

TEST_P(LongSequence, MappedSequenceIsAsAccurateAsIntegratingEveryContact) {
  const Scene s = LawScene(GetParam());
  const Simulation ref = RunWith(s, false, 1e-12);
  const Simulation integrated = RunWith(s, false, 1e-9);
  const Simulation mapped = RunWith(s, true, 1e-9);
  ASSERT_GT(ref.impacts.size(), 1000u);  // a long tail: what the map is for
  EXPECT_EQ(mapped.stop_reason, ref.stop_reason);
  EXPECT_EQ(mapped.impacts.size(), ref.impacts.size());
  EXPECT_EQ(integrated.mapped_contacts, 0);
  // Most contacts come from the map, and those report no steps of their own.
  EXPECT_GT(mapped.mapped_contacts, static_cast<int>(ref.impacts.size()) / 2);
  EXPECT_GE(mapped.map_panels, 3);
  const long zero_steps = std::count_if(mapped.impacts.begin(), mapped.impacts.end(),
                                        [](const SimImpact& i) { return i.steps == 0; });
  EXPECT_EQ(zero_steps, mapped.mapped_contacts);
  // Far fewer integrator steps in all, the map's own integrations included.
  EXPECT_LT(mapped.total_steps, integrated.total_steps / 5);

  const Errors em = Against(mapped, ref), ei = Against(integrated, ref);
  SCOPED_TRACE("mapped: v_in " + std::to_string(em.v_in) + " e " + std::to_string(em.e) + " t " +
               std::to_string(em.time_s) + "; integrated: v_in " + std::to_string(ei.v_in) + " e " +
               std::to_string(ei.e) + " t " + std::to_string(ei.time_s));
  EXPECT_LE(em.v_in, ei.v_in);
  EXPECT_LE(em.e, std::max(ei.e, 1e-9));
  EXPECT_LE(em.time_s, ei.time_s);
  // The energy ledger still balances to the integrator's level.
  EXPECT_LE(std::abs(mapped.energy.balance_error_j), 1e-8 * mapped.energy.initial_j);
}

INSTANTIATE_TEST_SUITE_P(HuntCrossleyFamily, LongSequence,
                         ::testing::Values("hunt-crossley", "hunt-crossley-hc", "hunt-crossley-ln",
                                           "hunt-crossley-flores"),
                         [](const auto& param_info) {
                           std::string n = param_info.param;
                           std::replace(n.begin(), n.end(), '-', '_');
                           return n;
                         });

TEST(ContactMapOption, OffByDefaultAndOffForShortSequences) {
  Scene s = LawScene("hunt-crossley-ln");
  {
    const auto law = CreateLaw(s.law, s);
    const Simulation d = Simulate(s, *law, law->ParameterValues(), SimulatorOptions{});
    EXPECT_EQ(d.mapped_contacts, 0);
    EXPECT_EQ(d.map_panels + d.map_panels_refused, 0);
  }
  // 30 impacts cannot repay a panel: nothing is built, every contact is integrated.
  s.limits.max_impacts = 30;
  const Simulation few = RunWith(s, true, 1e-9);
  ASSERT_EQ(few.impacts.size(), 30u);
  EXPECT_EQ(few.map_panels + few.map_panels_refused, 0);
  for (const SimImpact& i : few.impacts) EXPECT_GT(i.steps, 0);
  // Nor below the tolerance the map supports.
  s.limits.max_impacts = 3000;
  const Simulation tight = RunWith(s, true, 1e-12);
  EXPECT_EQ(tight.map_panels + tight.map_panels_refused, 0);
}

// ContactMap on its own, with a made-up contact: e(v) and the other outcomes given in closed
// form, so that what the panel interpolates is known exactly.
ContactRun MadeUp(double v, bool jump) {
  ContactRun r;
  r.end = ContactRun::End::kSeparated;
  double e = 0.999 - 0.01 * v + 0.002 * std::log(v) * std::log(v) * 1e-3;
  if (jump && v < 0.0075) e -= 1e-6;  // a discontinuity inside [0.005, 0.01]
  r.v_out_m_s = e * v;
  r.contact_s = 1e-4 * std::pow(v, -0.2);
  r.peak_overlap_m = 1e-5 * std::pow(v, 0.8);
  r.peak_force_n = 50.0 * std::pow(v, 1.2);
  r.work_j = 0.5 * (1.0 - e * e) * v * v;  // mass 1 kg
  r.ball_energy_end_j = 0.5 * e * e * v * v;
  r.contact_time_scale_s = r.contact_s;
  r.steps = 20;
  return r;
}

ContactRunOptions Opts() {
  ContactRunOptions o;
  o.rel_tolerance = 1e-9;
  return o;
}

TEST(ContactMap, InterpolatesASmoothOutcomeAndChecksThePanel) {
  int calls = 0;
  double tightest = 1.0;
  ContactMap map(
      [&](double v, const ContactRunOptions& o) {
        ++calls;
        tightest = std::min(tightest, o.rel_tolerance);
        return MadeUp(v, false);
      },
      Opts(), 1.0, 1e-4, 1e-6);
  // Too few contacts expected: no panel, no integration.
  EXPECT_FALSE(map.Find(0.01, 1e-4, 10.0));
  EXPECT_EQ(calls, 0);
  const auto r = map.Find(0.01, 1e-4, 1e6);
  ASSERT_TRUE(r);
  EXPECT_EQ(calls, ContactMap::kNodes + ContactMap::kChecks);
  EXPECT_DOUBLE_EQ(tightest, 1e-9 / ContactMap::kTighten);
  EXPECT_EQ(map.panels(), 1);
  EXPECT_EQ(map.steps(), 20L * calls);
  EXPECT_EQ(r->steps, 0);
  // Anywhere in [0.005, 0.01], without integrating again, within a small part of the tolerance.
  for (double v : {0.01, 0.0093, 0.0071, 0.0052, 0.005}) {
    const auto m = map.Find(v, 1e-4, 1e6);
    ASSERT_TRUE(m) << v;
    const ContactRun x = MadeUp(v, false);
    EXPECT_NEAR(m->v_out_m_s / v, x.v_out_m_s / v, 1e-12) << v;
    EXPECT_NEAR(m->contact_s, x.contact_s, 1e-10 * x.contact_s) << v;
    EXPECT_NEAR(m->peak_force_n, x.peak_force_n, 1e-10 * x.peak_force_n) << v;
    EXPECT_NEAR(m->work_j, x.work_j, 1e-12 * 0.5 * v * v) << v;
    EXPECT_EQ(m->end, ContactRun::End::kSeparated);
  }
  EXPECT_EQ(calls, ContactMap::kNodes + ContactMap::kChecks);
  // Below the panel a new one is needed; a rebound at the stuck speed is left to the integrator.
  EXPECT_TRUE(map.Find(0.004, 1e-4, 1e6));
  EXPECT_EQ(map.panels(), 2);
  EXPECT_FALSE(map.Find(0.004, 0.004, 1e6));
}

TEST(ContactMap, RefusesAPanelItsCheckContradicts) {
  int calls = 0;
  ContactMap map(
      [&](double v, const ContactRunOptions&) {
        ++calls;
        return MadeUp(v, true);
      },
      Opts(), 1.0, 1e-4, 1e-6);
  EXPECT_FALSE(map.Find(0.01, 1e-4, 1e6));
  EXPECT_EQ(map.refused(), 1);
  EXPECT_EQ(map.panels(), 0);
  // The refused panel is remembered: its speeds go to the integrator without a new attempt.
  const int after = calls;
  EXPECT_FALSE(map.Find(0.008, 1e-4, 1e6));
  EXPECT_EQ(calls, after);
}

TEST(ContactMap, RefusesAPanelWithAStuckNode) {
  ContactMap map(
      [&](double v, const ContactRunOptions&) {
        ContactRun r = MadeUp(v, false);
        if (v < 0.006) r.end = ContactRun::End::kStuck;
        return r;
      },
      Opts(), 1.0, 1e-4, 1e-6);
  EXPECT_FALSE(map.Find(0.01, 1e-4, 1e6));
  EXPECT_EQ(map.refused(), 1);
}

}  // namespace
}  // namespace bouncecal
