// Yade script of seed 003's column (column.hpp) for the Debian 12 build (Yade 2023.02a): the
// paper's own code and contact law.
//
// Classes (Yade reference: FrictMat, Ip2_FrictMat_FrictMat_MindlinPhys, MatchMaker,
// Law2_ScGeom_MindlinPhys_Mindlin, utils.wall, utils.sphere(fixed=True), NewtonIntegrator):
//   betan per material pair (MatchMaker): bead-bead from the bead fit, bead-floor and bead-wall
//   from the wall fit; krot and eta (rolling limit eta R_mean F_n) for every contact;
//   includeMoment=True. NewtonIntegrator(damping=0): Yade's default numerical damping (0.2)
//   would dissipate energy the fits do not. The beads and floor come from column.data (the file
//   LAMMPS reads); the run writes the same dump format as LAMMPS, and "Loop time" lines in
//   LAMMPS' wording, so run.sh treats both alike. O.numThreads is Yade's -j.
#include <sstream>

#include "bouncecal/core/user_text.hpp"
#include "export/column_deck.hpp"
#include "export/deck.hpp"

namespace bouncecal::exporter {

std::string YadeColumnScript(const ColumnPlan& p, const std::vector<std::string>& comments) {
  const double h_trim = ColumnPaper::kColumnHeight_m - 0.5 * p.d_mean_m;
  std::ostringstream os;
  os << CommentBlock(comments, "# ");
  os << "# Run: yade -j N -n -x column.py   (BOUNCECAL_SETTLE_STEPS=N, BOUNCECAL_COLLAPSE_STEPS=N\n"
     << "# to shorten; run.sh does this and writes profile.csv, front.csv, summary.json)\n"
     << "import math, os, time\n\n"
     << "settle_steps = int(os.environ.get('BOUNCECAL_SETTLE_STEPS', '" << p.settle_steps << "'))\n"
     << "collapse_steps = int(os.environ.get('BOUNCECAL_COLLAPSE_STEPS', '" << p.collapse_steps
     << "'))\n"
     << "dt = " << FormatShortest(p.time_step_s) << "\n"
     << "rest_speed = " << FormatShortest(p.rest_speed_m_s) << "\n"
     << "phi = math.atan(" << FormatShortest(ColumnPaper::kFriction) << ")\n"
     << "bead = O.materials.append(FrictMat(young=" << FormatShortest(ColumnPaper::kYoungs_pa)
     << ", poisson=" << FormatShortest(p.poisson_ratio)
     << ", frictionAngle=phi, density=" << FormatShortest(ColumnPaper::kDensity_kg_m3)
     << ", label='bead'))\n"
     << "floor = O.materials.append(FrictMat(young=" << FormatShortest(ColumnPaper::kYoungs_pa)
     << ", poisson=" << FormatShortest(p.poisson_ratio)
     << ", frictionAngle=phi, density=" << FormatShortest(ColumnPaper::kDensity_kg_m3)
     << ", label='floor'))\n"
     << "# plastic walls (E = " << FormatShortest(p.wall_youngs_pa) << " Pa) stiffened to "
     << FormatShortest(p.yade_wall_youngs_pa) << " Pa: Yade takes R/2 against a wall\n"
     << "wall = O.materials.append(FrictMat(young=" << FormatShortest(p.yade_wall_youngs_pa)
     << ", poisson=" << FormatShortest(p.wall_poisson)
     << ", frictionAngle=phi, density=1200, label='wall'))\n"
     << "beads = []\n"
     << "with open('column.data') as f:\n"
     << "    atoms = False\n"
     << "    for line in f:\n"
     << "        w = line.split()\n"
     << "        if line.startswith('Atoms'):\n"
     << "            atoms = True\n"
     << "        elif atoms and len(w) == 7:\n"
     << "            kind, d = int(w[1]), float(w[2])\n"
     << "            c = (float(w[4]), float(w[5]), float(w[6]))\n"
     << "            if kind == 1:\n"
     << "                beads.append(O.bodies.append(utils.sphere(c, d / 2, material=bead)))\n"
     << "            else:\n"
     << "                O.bodies.append(utils.sphere(c, d / 2, material=floor, fixed=True))\n"
     << "for pos, axis, sense in [((0, 0, 0), 0, 1), (("
     << FormatShortest(ColumnPaper::kBoxLength_m) << ", 0, 0), 0, -1), ((0, 0, 0), 1, 1), ((0, "
     << FormatShortest(ColumnPaper::kBoxWidth_m) << ", 0), 1, -1), ((0, 0, 0), 2, 1)]:\n"
     << "    O.bodies.append(utils.wall(pos, axis=axis, sense=sense, material=wall))\n"
     << "gate = O.bodies.append(utils.wall((" << FormatShortest(ColumnPaper::kColumnLength_m)
     << ", 0, 0), axis=0, sense=-1, material=wall))\n"
     << "bb, bw = " << FormatShortest(p.bead_bead.yade_betan) << ", "
     << FormatShortest(p.bead_wall.yade_betan) << "\n"
     << "betan = MatchMaker(matches=((bead, bead, bb), (bead, floor, bw), (bead, wall, bw),\n"
     << "                            (floor, floor, bw), (floor, wall, bw), (wall, wall, bw)))\n"
     << "O.engines = [\n"
     << "    ForceResetter(),\n"
     << "    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()]),\n"
     << "    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],\n"
     << "                    [Ip2_FrictMat_FrictMat_MindlinPhys(betan=betan, krot="
     << FormatShortest(p.rolling_stiffness_nm_rad) << ", eta=" << FormatShortest(p.rolling_friction)
     << ")],\n"
     << "                    [Law2_ScGeom_MindlinPhys_Mindlin(includeMoment=True)]),\n"
     << "    NewtonIntegrator(damping=0, gravity=(0, 0, -9.8)),\n"
     << "]\n"
     << "O.dt = dt\n\n"
     << "def live():\n"
     << "    return [b for b in beads if O.bodies[b] is not None]\n\n"
     << "def vrms():\n"
     << "    ids = live()\n"
     << "    m = sum(O.bodies[i].state.mass for i in ids)\n"
     << "    k = sum(O.bodies[i].state.mass * O.bodies[i].state.vel.squaredNorm() for i in ids)\n"
     << "    return math.sqrt(k / m)\n\n"
     << "def dump(f, step):\n"
     << "    ids = live()\n"
     << "    f.write('ITEM: TIMESTEP\\n%d\\nITEM: NUMBER OF ATOMS\\n%d\\n' % (step, len(ids)))\n"
     << "    f.write('ITEM: BOX BOUNDS ff ff ff\\n0 " << FormatShortest(ColumnPaper::kBoxLength_m)
     << "\\n0 " << FormatShortest(ColumnPaper::kBoxWidth_m) << "\\n0 "
     << FormatShortest(p.box_top_m) << "\\nITEM: ATOMS id x y z radius\\n')\n"
     << "    for i in ids:\n"
     << "        b = O.bodies[i]\n"
     << "        f.write('%d %.9g %.9g %.9g %.9g\\n' % (i + 1, b.state.pos[0], b.state.pos[1], "
        "b.state.pos[2], b.shape.radius))\n\n"
     << "def phase(steps, t_min, every, on_chunk):\n"
     << "    # Runs until at rest (rms speed) after t_min, or `steps`; on_chunk(step) every "
        "`every`.\n"
     << "    start, done, at_rest = time.time(), 0, False\n"
     << "    on_chunk(0)\n"
     << "    while done < steps:\n"
     << "        n = min(every, steps - done)\n"
     << "        O.run(n, True)\n"
     << "        done += n\n"
     << "        on_chunk(done)\n"
     << "        if done * dt > t_min and vrms() < rest_speed:\n"
     << "            at_rest = True\n"
     << "            break\n"
     << "    print('Loop time of %g on %d procs for %d steps with %d atoms' % (time.time() - "
        "start, "
        "O.numThreads, done, len(O.bodies)))\n"
     << "    return done, at_rest\n\n"
     << "steps, _ = phase(settle_steps, " << FormatShortest(p.settle_min_s)
     << ", 100, lambda s: None)\n"
     << "print('column: settled after %d steps, top %g m' % (steps, max(O.bodies[i].state.pos[2] + "
        "O.bodies[i].shape.radius for i in beads)))\n"
     << "for i in beads:\n"
     << "    if O.bodies[i].state.pos[2] > " << FormatShortest(h_trim) << ":\n"
     << "        O.bodies.erase(i)\n"
     << "O.bodies.erase(gate)\n"
     << "ids = live()\n"
     << "print('column: beads %d floor %d box 0 " << FormatShortest(ColumnPaper::kBoxLength_m)
     << " 0 " << FormatShortest(ColumnPaper::kBoxWidth_m) << " 0 " << FormatShortest(p.box_top_m)
     << "' % (len(ids), sum(1 for b in O.bodies if b is not None and b.material.label == "
        "'floor')))\n"
     << "ip2 = O.engines[2].physDispatcher.functors[0]\n"
     << "print('column: yade betan bead-bead %.17g bead-floor %.17g bead-wall %.17g krot %.17g "
        "eta %.17g dt %.17g' % (ip2.betan(bead, bead), ip2.betan(bead, floor), ip2.betan(bead, "
        "wall), "
        "ip2.krot, ip2.eta, O.dt))\n"
     << "out = open('column.dump', 'w')\n"
     << "every = " << p.dump_every << "\n"
     << "steps, rest = phase(collapse_steps, " << FormatShortest(ColumnPaper::kFrameInterval_s)
     << ", every, lambda s: dump(out, s))\n"
     << "out.close()\n"
     << "with open('rest.dump', 'w') as f:\n"
     << "    dump(f, steps)\n"
     << "print('column: collapse ended after %d steps, t = %g s, at rest %d' % (steps, steps * dt, "
        "rest))\n";
  return os.str();
}

}  // namespace bouncecal::exporter
