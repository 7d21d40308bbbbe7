// Data sets for quadkit-bench (see data.h).
#include "data.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>

namespace qkb {

std::string shared_data(const std::string &name) {
  const char *shared = getenv("QK_SHARED_DIR");
  return (shared && *shared ? std::string(shared) + "/data" : std::string(QKB_DATA_DIR)) + "/" +
         name;
}

namespace {

double clamp01(double v) { return v < 0 ? 0 : v > 1 ? 1 : v; }

uint64_t seed_of(const std::string &name, size_t n) {
  uint64_t h = 1469598103934665603ull;
  for (char c : name) h = (h ^ (unsigned char)c) * 1099511628211ull;
  return h ^ (n * 0x9e3779b97f4a7c15ull);
}

std::vector<Pt> uniform(size_t n, std::mt19937_64 &rng) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Pt> p(n);
  for (auto &q : p) q = {u(rng), u(rng)};
  return p;
}

std::vector<Pt> gauss(size_t n, std::mt19937_64 &rng) {
  std::uniform_real_distribution<double> u(0, 1);
  const int m = 64;
  double cx[m], cy[m], sd[m], cum[m], total = 0;
  for (int i = 0; i < m; i++) {
    cx[i] = 0.05 + 0.9 * u(rng);
    cy[i] = 0.05 + 0.9 * u(rng);
    sd[i] = 0.002 + 0.04 * u(rng);
    total += 1.0 / (i + 1);
    cum[i] = total;
  }
  std::normal_distribution<double> g(0, 1);
  std::vector<Pt> p(n);
  for (auto &q : p) {
    double w = u(rng) * total;
    int i = (int)(std::lower_bound(cum, cum + m, w) - cum);
    if (i >= m) i = m - 1;
    q = {clamp01(cx[i] + sd[i] * g(rng)), clamp01(cy[i] + sd[i] * g(rng))};
  }
  return p;
}

std::vector<Pt> polyline(size_t n, std::mt19937_64 &rng) {
  std::uniform_real_distribution<double> u(0, 1);
  const int lines = 16, verts = 32;
  std::vector<Pt> a, b;
  std::vector<double> cum;
  double total = 0;
  for (int l = 0; l < lines; l++) {
    Pt v = {u(rng), u(rng)};
    for (int i = 0; i < verts - 1; i++) {
      Pt w = {clamp01(v.x + 0.2 * (u(rng) - 0.5)), clamp01(v.y + 0.2 * (u(rng) - 0.5))};
      a.push_back(v);
      b.push_back(w);
      total += std::hypot(w.x - v.x, w.y - v.y);
      cum.push_back(total);
      v = w;
    }
  }
  std::vector<Pt> p(n);
  for (auto &q : p) {
    double w = u(rng) * total;
    size_t i = std::lower_bound(cum.begin(), cum.end(), w) - cum.begin();
    if (i >= cum.size()) i = cum.size() - 1;
    double t = u(rng);
    q = {a[i].x + t * (b[i].x - a[i].x), a[i].y + t * (b[i].y - a[i].y)};
  }
  return p;
}

std::vector<Pt> degenerate(size_t n, std::mt19937_64 &rng) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Pt> p;
  p.reserve(n);
  Pt loc[64];
  for (auto &l : loc) l = {u(rng), u(rng)};
  size_t third = n / 3;
  for (size_t i = 0; i < third; i++) p.push_back(loc[rng() % 64]);
  for (size_t i = 0; i < third; i++) {
    double t = u(rng);
    p.push_back(i % 2 ? Pt{t, t} : Pt{t, 0.5});
  }
  size_t g = 1;
  while (g * g < n - 2 * third) g *= 2;
  for (size_t i = 2 * third; i < n; i++)
    p.push_back({(double)(rng() % (g + 1)) / (double)g, (double)(rng() % (g + 1)) / (double)g});
  std::shuffle(p.begin(), p.end(), rng);
  return p;
}

std::vector<Pt> cities(size_t cap, std::string *why) {
  std::string path = shared_data("cities.csv");
  FILE *f = fopen(path.c_str(), "r");
  std::vector<Pt> p;
  if (!f) {
    if (why) *why = path + ": " + strerror(errno);
    return p;
  }
  char line[4096];
  bool first = true;
  while (fgets(line, sizeof line, f)) {
    char *end;
    double lon = strtod(line, &end);
    if (end == line || *end != ',') {
      if (first) {
        first = false;
        continue; // the header
      }
      continue;
    }
    first = false;
    char *s = end + 1;
    double lat = strtod(s, &end);
    if (end == s) continue;
    p.push_back({lon, lat});
  }
  fclose(f);
  if (p.size() > cap) {
    // Keep an evenly spaced subset, which keeps the file's (country-grouped) mixture.
    std::vector<Pt> q;
    double step = (double)p.size() / (double)cap;
    for (size_t i = 0; i < cap; i++) q.push_back(p[(size_t)(i * step)]);
    p.swap(q);
  }
  if (p.empty() && why) *why = path + ": no rows";
  return p;
}

} // namespace

std::vector<Pt> make_dataset(const std::string &name, size_t n, std::string *why) {
  std::mt19937_64 rng(seed_of(name, n));
  std::vector<Pt> p;
  if (name == "cities") return cities(n, why);
  if (name == "uniform")
    p = uniform(n, rng);
  else if (name == "gauss")
    p = gauss(n, rng);
  else if (name == "polyline")
    p = polyline(n, rng);
  else if (name == "degenerate")
    p = degenerate(n, rng);
  else {
    if (why) *why = "unknown data set '" + name + "'";
    return p;
  }
  if (n >= 2) {
    p[0] = {0, 0};
    p[1] = {1, 1};
  }
  return p;
}

std::vector<Pt> make_queries(const std::vector<Pt> &pts, size_t nq, uint64_t seed) {
  std::mt19937_64 rng(seed);
  double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
  for (const Pt &p : pts) {
    xmin = std::min(xmin, p.x), xmax = std::max(xmax, p.x);
    ymin = std::min(ymin, p.y), ymax = std::max(ymax, p.y);
  }
  double side = std::max(xmax - xmin, ymax - ymin);
  double h = side / std::sqrt((double)pts.size());
  std::uniform_real_distribution<double> u(-h, h);
  std::vector<Pt> q(nq);
  for (auto &v : q) {
    const Pt &p = pts[rng() % pts.size()];
    v = {p.x + u(rng), p.y + u(rng)};
  }
  return q;
}

namespace {
uint64_t spread(uint32_t v) {
  uint64_t x = v;
  x = (x | (x << 16)) & 0x0000FFFF0000FFFFull;
  x = (x | (x << 8)) & 0x00FF00FF00FF00FFull;
  x = (x | (x << 4)) & 0x0F0F0F0F0F0F0F0Full;
  x = (x | (x << 2)) & 0x3333333333333333ull;
  x = (x | (x << 1)) & 0x5555555555555555ull;
  return x;
}
} // namespace

void morton_sort(std::vector<Pt> &qs) {
  if (qs.empty()) return;
  double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
  for (const Pt &p : qs) {
    xmin = std::min(xmin, p.x), xmax = std::max(xmax, p.x);
    ymin = std::min(ymin, p.y), ymax = std::max(ymax, p.y);
  }
  double s = std::max(xmax - xmin, ymax - ymin);
  if (!(s > 0)) s = 1;
  std::vector<std::pair<uint64_t, Pt>> k(qs.size());
  for (size_t i = 0; i < qs.size(); i++) {
    uint32_t ix = (uint32_t)std::min(4294967295.0, (qs[i].x - xmin) / s * 4294967295.0);
    uint32_t iy = (uint32_t)std::min(4294967295.0, (qs[i].y - ymin) / s * 4294967295.0);
    k[i] = {spread(ix) | (spread(iy) << 1), qs[i]};
  }
  std::sort(k.begin(), k.end(),
            [](const std::pair<uint64_t, Pt> &a, const std::pair<uint64_t, Pt> &b) {
              return a.first < b.first;
            });
  for (size_t i = 0; i < qs.size(); i++) qs[i] = k[i].second;
}

std::vector<Box> make_boxes(size_t n, double hmax, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Box> b(n);
  for (auto &x : b) {
    double cx = u(rng), cy = u(rng), hx = hmax * u(rng), hy = hmax * u(rng);
    x = {cx - hx, cy - hy, cx + hx, cy + hy};
  }
  return b;
}

std::vector<double> make_discs(size_t n, double rmax, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> d(3 * n);
  for (size_t i = 0; i < n; i++) {
    d[3 * i] = u(rng);
    d[3 * i + 1] = u(rng);
    d[3 * i + 2] = rmax * u(rng);
  }
  return d;
}

std::vector<Ray> make_rays(size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Ray> r(n);
  for (auto &v : r) {
    float a = 6.2831853f * u(rng);
    v = {(double)u(rng), (double)u(rng), (double)std::cos(a), (double)std::sin(a)};
  }
  return r;
}

std::vector<Ring> make_octagons(unsigned U, unsigned g, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Ring> rings;
  unsigned cell = U / g;
  for (unsigned i = 0; i < g; i++)
    for (unsigned j = 0; j < g; j++) {
      // Octagon of half-width a with corners cut by b, inside its grid cell with a
      // margin of at least 2, its centre jittered.
      long a = (long)(cell / 4 + rng() % (cell / 8 + 1));
      long b = a / 2;
      long slack = (long)cell / 2 - a - 2;
      long cx =
          (long)(i * cell + cell / 2) + (slack > 0 ? (long)(rng() % (2 * slack + 1)) - slack : 0);
      long cy =
          (long)(j * cell + cell / 2) + (slack > 0 ? (long)(rng() % (2 * slack + 1)) - slack : 0);
      Ring r = {{(double)(cx - a + b), (double)(cy - a)}, {(double)(cx + a - b), (double)(cy - a)},
                {(double)(cx + a), (double)(cy - a + b)}, {(double)(cx + a), (double)(cy + a - b)},
                {(double)(cx + a - b), (double)(cy + a)}, {(double)(cx - a + b), (double)(cy + a)},
                {(double)(cx - a), (double)(cy + a - b)}, {(double)(cx - a), (double)(cy - a + b)}};
      rings.push_back(r);
    }
  return rings;
}

} // namespace qkb
