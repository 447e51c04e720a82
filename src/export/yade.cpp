// Yade script (bounce) for the Debian 12 build (Yade 2023.02a).
//
// Classes (Yade reference: ViscoelasticPM, HertzMindlin):
//   ViscElMat(kn, cn) + Ip2_ViscElMat_ViscElMat_ViscElPhys + Law2_ScGeom_ViscElPhys_Basic:
//     F = max(0, kn d + cn v_n); the contact's kn, cn are the series combination of both
//     materials' values (1/kn = 1/kn1 + 1/kn2), so both materials carry 2k and 2c. (Given as
//     tc, en instead, the wall's zero mass is replaced by the sphere's and the reduced mass
//     becomes m/2: e = 0.858 for 0.8 requested — avoided here.)
//   FrictMat(young, poisson) + Ip2_FrictMat_FrictMat_MindlinPhys(betan) +
//   Law2_ScGeom_MindlinPhys_Mindlin: F = max(0, Kno d^1.5 + 2 betan sqrt(m 3/2 Kno) d^1/4 v_n),
//     Kno = 4/3 E* sqrt(R'), E* = E1 E2 / ((1 - nu1^2) E2 + (1 - nu2^2) E1), and against a wall
//     R' = R/2 (the wall takes the sphere's radius).
// NewtonIntegrator(damping=0): Yade's default numerical damping (0.2) would dissipate energy.
#include <sstream>

#include "bouncecal/core/format.hpp"
#include "export/deck.hpp"

namespace bouncecal::exporter {

std::string YadeBounceScript(const DeckInput& in) {
  const Mapping& m = in.mapping;
  const auto& c = m.coefficients;
  const double r = in.radius_m, z0 = r + in.release_height_m;
  std::ostringstream os;
  os << CommentBlock(in.comments, "# ");
  os << "# Run: yade -n -x bounce.py   (BOUNCECAL_STEPS=N to shorten; run.sh does this and\n"
     << "# writes impacts.csv)\n"
     << "import os\n\n"
     << "steps = int(os.environ.get('BOUNCECAL_STEPS', '" << in.steps << "'))\n";
  if (m.form == NativeForm::kLinear) {
    os << "mat = O.materials.append(ViscElMat(kn=" << FormatShortest(c.at("kn_n_m"))
       << ", cn=" << FormatShortest(c.at("cn_n_s_m"))
       << ", ks=0, cs=0, frictionAngle=0, density=" << FormatShortest(in.density_kg_m3) << "))\n";
  } else {
    // Same material on both sides: E* = E / (2 (1 - nu^2)).
    const double nu = in.poisson_ratio;
    os << "mat = O.materials.append(FrictMat(young="
       << FormatShortest(2.0 * (1.0 - nu * nu) * c.at("young_eff_pa"))
       << ", poisson=" << FormatShortest(nu)
       << ", frictionAngle=0, density=" << FormatShortest(in.density_kg_m3) << "))\n";
  }
  os << "wall = O.bodies.append(utils.wall(0, axis=2, sense=1, material=mat))\n"
     << "ball = O.bodies.append(utils.sphere((0, 0, " << FormatShortest(z0) << "), "
     << FormatShortest(r) << ", material=mat))\n"
     << "trace = open('trace.csv', 'w')\n"
     << "trace.write('t_s,z_m,vz_m_s\\n')\n\n"
     << "def sample():\n"
     << "    s = O.bodies[ball].state\n"
     << "    trace.write('%.17g,%.17g,%.17g\\n' % (O.time, s.pos[2], s.vel[2]))\n\n";
  const std::string ip2 =
      m.form == NativeForm::kLinear
          ? "Ip2_ViscElMat_ViscElMat_ViscElPhys()"
          : "Ip2_FrictMat_FrictMat_MindlinPhys(betan=" + FormatShortest(c.at("betan")) + ")";
  const std::string law2 = m.form == NativeForm::kLinear ? "Law2_ScGeom_ViscElPhys_Basic()"
                                                         : "Law2_ScGeom_MindlinPhys_Mindlin()";
  os << "O.engines = [\n"
     << "    ForceResetter(),\n"
     << "    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()]),\n"
     << "    InteractionLoop([Ig2_Wall_Sphere_ScGeom()], [" << ip2 << "], [" << law2 << "]),\n"
     << "    NewtonIntegrator(damping=0, gravity=(0, 0, " << FormatShortest(-in.g_m_s2) << ")),\n"
     << "    PyRunner(iterPeriod=" << in.trace_every << ", command='sample()', initRun=True),\n"
     << "]\n"
     << "O.dt = " << FormatShortest(in.time_step_s) << "\n"
     << "O.run(steps, True)\n"
     << "trace.close()\n"
     << "print('bounce.py: %d steps, t = %g s' % (O.iter, O.time))\n";
  return os.str();
}

}  // namespace bouncecal::exporter
