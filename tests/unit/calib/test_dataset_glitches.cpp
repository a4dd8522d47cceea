// The glitch screen of jig datasets (src/calib/dataset/glitches.h): clean
// data loses nothing, injected spikes are set aside exactly (and nothing
// else), and what is left equals the file without them.
//
// The data is the project's simulator (Gaussian pot noise, ADC steps, the
// jig's errors) with fixed seeds, so every run sees the same numbers. The
// screen's level is 0.01 per dataset (Bonferroni over every reading): a
// clean dataset has one chance in a hundred of losing a sample, so the
// fixed seeds here are a handful of draws from that, not a tuning.
#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <set>
#include <setjmp.h>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include "calib/dataset/dataset.h"
#include "calib/dataset/simulate.h"

extern "C" {
#include <cmocka.h>
}
#include "jig_text.h"

using namespace cdm;
using namespace cdm::test;

namespace {

JigSimOptions small_jig(uint64_t seed) {
    JigSimOptions o;
    o.n = 9;
    o.heights = {30, 50, 70};
    o.samples = 100;
    o.seed = seed;
    return o;
}

} // namespace

// Clean jigs of several kinds lose nothing: the seed's sampling, a sparse
// jig (10 samples: the medians and MADs are rough), and pots quieter than
// their ADC step (readings repeat; one step is never a glitch).
static void clean_jigs_lose_nothing(void **) {
    for (uint64_t seed = 1; seed <= 3; ++seed) {
        JigSimOptions dense = small_jig(seed), sparse = small_jig(seed), quiet = small_jig(seed), three = small_jig(seed);
        sparse.samples = 10;
        sparse.noise_mm = 0.25;
        quiet.noise_mm = 0.002;
        three.samples = 3; // the median of three: its own uncertainty counts
        for (const JigSimOptions *o : {&dense, &sparse, &quiet, &three}) {
            Dataset d;
            std::string err;
            assert_true(parse_dataset(join(simulated_lines(*o)), "clean.csv", d, err));
            if (!d.glitches.empty())
                fail_msg("seed %llu, %d samples, noise %.3f: %zu clean samples set aside (line %zu, %.1f sd)",
                         (unsigned long long)seed, o->samples, o->noise_mm, d.glitches.size(), d.glitches[0].line,
                         d.glitches[0].z);
            assert_true(d.glitch_z > 4.0 && d.glitch_z < 6.5);
            // The pooled noise scale is the simulator's, or the ADC step when
            // the noise is below it. It is the median of N positions'
            // variances of k = n - 1 dof, each chi2(k)/k with sd sqrt(2/k);
            // a sample median has standard error about 1.2533 sd / sqrt(N)
            // (Gaussian approximation), and the sd half the variance's
            // relative error: within 5 of those (and 0.5 % for the ADC
            // steps' own dither in the variance).
            const double k = o->samples - 1, N = double(d.pos.size());
            const double tol = 5 * 0.5 * 1.2533 * std::sqrt(2 / k) / std::sqrt(N) + 0.005;
            for (int c = 0; c < 4; ++c) {
                const double want = std::max(o->noise_mm, o->quant_mm);
                if (std::fabs(d.glitch_scale[c] - want) > tol * want)
                    fail_msg("cable %d noise scale %.4f mm, simulated %.4f (tolerance %.1f %%)", c + 1, d.glitch_scale[c],
                             want, 100 * tol);
            }
        }
    }
}

// Spikes from 10 to 200 times the noise, on random rows and cables, a few
// at the same position: every one is set aside with its line and cable,
// nothing else is, and each position's statistics equal the file's without
// those lines, bit for bit (the same rows accumulated in the same order).
static void spikes_are_set_aside_exactly(void **) {
    for (int samples : {100, 10}) {
        JigSimOptions o = small_jig(7);
        o.samples = samples;
        std::vector<std::string> lines = simulated_lines(o);
        std::mt19937_64 rng(42);
        std::set<size_t> hit;
        std::vector<int> cable_of(lines.size(), -1);
        while (hit.size() < 30) {
            const size_t k = 1 + size_t(rng() % (lines.size() - 1));
            if (hit.count(k)) continue;
            const int c = int(rng() % 4);
            const double mm = (rng() % 2 ? 1 : -1) * 0.05 * (10 + double(rng() % 191));
            spike(lines, k, c, mm);
            hit.insert(k);
            cable_of[k] = c;
        }
        // A second spike at the position of the first one (its neighbour row).
        const size_t twin = *hit.begin() + 1;
        if (!hit.count(twin)) {
            spike(lines, twin, 2, 3.0);
            hit.insert(twin);
            cable_of[twin] = 2;
        }
        Dataset d;
        std::string err;
        assert_true(parse_dataset(join(lines), "spiky.csv", d, err));
        assert_int_equal(d.glitches.size(), hit.size());
        assert_int_equal(d.rows, lines.size() - 1);
        for (auto &g : d.glitches) {
            if (!hit.count(g.line - 1)) fail_msg("line %zu set aside but not spiked", g.line);
            assert_int_equal(g.cable, cable_of[g.line - 1] + 1);
            assert_true(g.z > d.glitch_z);
        }
        std::vector<std::string> without;
        for (size_t k = 0; k < lines.size(); ++k)
            if (!hit.count(k)) without.push_back(lines[k]);
        Dataset ref;
        assert_true(parse_dataset(join(without), "without.csv", ref, err));
        assert_int_equal(ref.pos.size(), d.pos.size());
        for (size_t g = 0; g < d.pos.size(); ++g) {
            assert_int_equal(d.pos[g].n, ref.pos[g].n);
            for (int c = 0; c < 4; ++c) {
                assert_true(d.pos[g].mean[c] == ref.pos[g].mean[c]);
                for (int k = 0; k < 4; ++k) assert_true(d.pos[g].cov[c][k] == ref.pos[g].cov[c][k]);
            }
        }
        // Judged position by position: a file written as a jig session
        // writes it (each position's samples together) holds one
        // position's samples at a time, not the file's.
        assert_true(d.glitch_held > 0 && d.glitch_held <= size_t(samples));
        // Read again, the rows set aside stay aside.
        size_t seen = 0;
        assert_true(for_each_sample(d, [&](size_t, const double *) { ++seen; }, err));
        assert_int_equal(seen, d.rows - d.glitches.size());
    }
}

// A position whose pots are really noisier (3 times the sd: a worn track)
// keeps its samples: they are judged against its own spread. A position
// whose samples fall in two groups (a cable that slipped half-way) is not
// "glitching" and is left whole.
static void noisy_or_bimodal_positions_are_left_whole(void **) {
    JigSimOptions o = small_jig(3);
    std::vector<std::string> lines = simulated_lines(o);
    std::mt19937_64 rng(5);
    std::normal_distribution<double> n01;
    // Rows 1-100 are the first position, 101-200 the second.
    for (size_t k = 1; k <= 100; ++k)
        for (int c = 0; c < 4; ++c) spike(lines, k, c, 2 * std::sqrt(2.0) * o.noise_mm * n01(rng));
    for (size_t k = 101 + 60; k <= 200; ++k) spike(lines, k, 1, 1.0);
    Dataset d;
    std::string err;
    assert_true(parse_dataset(join(lines), "uneven.csv", d, err));
    for (auto &g : d.glitches)
        fail_msg("line %zu (point %ld, cable %d, %.1f sd) set aside", g.line, g.point, g.cable, g.z);
    assert_int_equal(d.pos[0].n, 100);
    assert_int_equal(d.pos[1].n, 100);
}

// A point left out whole (the diagnosis' outliers) with a glitch inside it:
// the rows read again are the file's minus the glitches minus that point's.
static void point_left_out_with_its_glitch(void **) {
    JigSimOptions o = small_jig(11);
    std::vector<std::string> lines = simulated_lines(o);
    spike(lines, 150, 0, 4.0); // in the second position (rows 101-200)
    spike(lines, 420, 3, -3.0); // in the fifth
    Dataset d;
    std::string err;
    assert_true(parse_dataset(join(lines), "spiky.csv", d, err));
    assert_int_equal(d.glitches.size(), 2);
    const long second = d.pos[1].point;
    Dataset kept;
    assert_true(without_points(d, {second}, kept, err));
    assert_int_equal(kept.pos.size(), d.pos.size() - 1);
    assert_int_equal(kept.rows, d.rows);
    size_t seen = 0;
    assert_true(for_each_sample(kept, [&](size_t, const double *) { ++seen; }, err));
    assert_int_equal(seen, d.rows - 2 - 99); // 100 rows of the point, one of them the glitch already aside
    // The positions kept are the same, with the same statistics.
    for (size_t g = 0, k = 0; g < d.pos.size(); ++g) {
        if (d.pos[g].point == second) continue;
        assert_int_equal(kept.pos[k].point, d.pos[g].point);
        for (int c = 0; c < 4; ++c) assert_true(kept.pos[k].mean[c] == d.pos[g].mean[c]);
        ++k;
    }
    // Leaving out every point is refused, naming why.
    std::vector<long> all;
    for (auto &p : d.pos) all.push_back(p.point);
    assert_false(without_points(d, all, kept, err));
    assert_non_null(strstr(err.c_str(), "no position would be left"));
}

int main() {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(clean_jigs_lose_nothing),
        cmocka_unit_test(spikes_are_set_aside_exactly),
        cmocka_unit_test(noisy_or_bimodal_positions_are_left_whole),
        cmocka_unit_test(point_left_out_with_its_glitch),
    };
    return cmocka_run_group_tests(tests, nullptr, nullptr);
}
