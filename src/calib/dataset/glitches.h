// Glitch screening of a jig dataset (private to calib; read.cpp runs it
// as the file is loaded).
//
// A glitch is one sample whose reading departs from the rest of its
// position's samples by far more than the pots' noise allows: a spike of a
// wiper, a dropped ADC bit, a bumped cable. Left in, one 5 mm spike among
// 100 samples moves the position's mean by 0.05 mm (the noise floor's
// size) and multiplies its variance by about a hundred, and a tenth of a
// percent of such samples doubles the whole jig's noise floor and hides
// every small effect. The test, per reading:
//
//   |reading - median of its position's readings of that cable| > z * s,
//   s = max(the cable's pooled noise sd, the position's own 1.4826 * MAD),
//   z = the two-sided Gaussian quantile at 0.01 / (4 * rows) (Bonferroni
//       over every reading: on clean Gaussian data the screen sets aside a
//       sample in one dataset of a hundred), times sqrt(1 + pi / (2n)) for
//       the median's own uncertainty with n samples.
//
// The pooled sd is robust: the median over positions of their sample
// variances, each divided by the median of chi-square(n-1)/(n-1), so that
// the glitches themselves (which inflate some positions' variances without
// bound) do not widen it; it needs 10 positions of 3 samples or more, else
// nothing is screened. The position's own MAD keeps a position that is
// really noisier (a worn track) from being clipped: its samples are judged
// against its own spread. The floor is the readings' resolution (one ADC
// step is never a glitch). A position with fewer than 3 samples has no
// median to speak of and is not screened; one where more than a quarter of
// the samples would be set aside is not glitching but bimodal (a cable
// that slipped mid-position, two holes under one id) and is left whole for
// the fit's statistics to judge.
#pragma once

#include <array>
#include <cstdint>
#include <cstddef>
#include <vector>

#include "calib/dataset/dataset.h"

namespace cdm {

// One sample of a suspect position, kept for the screen's second pass.
struct ScreenSample {
    size_t g = 0;    // position index into Dataset::pos
    size_t row = 0;  // 0-based data row
    size_t line = 0; // 1-based file line
    double l[4] = {};
};

// A screen's threshold and which positions need a closer look.
struct GlitchScreen {
    double z = 0;               // threshold in robust sd (0: no screen)
    double scale[4] = {};       // the cables' pooled noise sd (mm)
    std::vector<char> suspect;  // per position: a reading may be a glitch
    bool any() const;
};

// Per position and cable, the range of the readings from the first pass:
// lo in [0, 4), hi in [4, 8).
using ReadingRange = std::array<double, 8>;

// The threshold's factor for the median's own error with n samples,
// sqrt(1 + pi / (2n)).
double glitch_inflation(int n);

// From the first pass's statistics: the threshold, the scales, and the
// positions that can hold a glitch (an extreme reading further from the
// mean than the threshold, less the readings' sd: see the .cpp).
GlitchScreen glitch_suspects(const Dataset &d, const std::vector<ReadingRange> &range);

// At most this many samples held at once (56 MiB); beyond, the screen gives
// up and sets nothing aside (Dataset::glitch_z = 0 says it did not run).
constexpr size_t kGlitchMaxHeld = size_t(1) << 20;

// The screen's second pass: fed each suspect position's samples as the
// rows come, it judges a position as soon as it holds all of them (their
// count is known from the first pass) and lets them go, so a file written
// position by position (a jig session) holds one position's samples at a
// time; an interleaved file holds those of the positions still open.
class GlitchJudge {
public:
    GlitchJudge(const Dataset &d, const GlitchScreen &s) : d_(d), s_(s) {}
    void add(const ScreenSample &x);
    // The glitches, by line, and their data rows, sorted.
    void finish(std::vector<DatasetGlitch> &glitches, std::vector<size_t> &rows);
    size_t peak_samples() const { return peak_; } // most samples held at once
    bool abandoned() const { return abandoned_; }   // kGlitchMaxHeld reached: nothing set aside

private:
    void judge(std::vector<ScreenSample> &samples);
    const Dataset &d_;
    const GlitchScreen &s_;
    std::vector<std::vector<ScreenSample>> open_; // per position, until complete
    size_t held_ = 0, peak_ = 0;
    bool abandoned_ = false;
    std::vector<DatasetGlitch> glitches_;
    std::vector<size_t> rows_;
};

} // namespace cdm
