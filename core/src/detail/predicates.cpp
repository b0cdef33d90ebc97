// predicates.cpp: floating-point filter, then exact expansion arithmetic (Shewchuk 1997).
#include "detail/predicates.h"

#include <cmath>
#include <stdexcept>

namespace riemesh::detail {

namespace {

constexpr double kEpsilon = 1.1102230246251565e-16; // 2^-53: half an ulp of 1
// Relative error bounds of the floating-point determinants (Shewchuk, "Adaptive precision
// floating-point arithmetic and fast robust geometric predicates", section 4): they include the
// rounding of the initial coordinate differences.
constexpr double kOrient2dBound = (3.0 + 16.0 * kEpsilon) * kEpsilon;
constexpr double kOrient3dBound = (7.0 + 56.0 * kEpsilon) * kEpsilon;

/// x + y = a + b exactly, x = fl(a + b) (Knuth).
inline void twoSum(double a, double b, double& x, double& y)
{
    x = a + b;
    const double bVirtual = x - a;
    const double aVirtual = x - bVirtual;
    y = (a - aVirtual) + (b - bVirtual);
}

/// hi + lo = a, each with at most 26 significant bits (Dekker).
inline void split(double a, double& hi, double& lo)
{
    const double c = 134217729.0 * a; // 2^27 + 1
    hi = c - (c - a);
    lo = a - hi;
}

/// x + y = a * b exactly, x = fl(a * b) (Dekker; needs no fused multiply-add).
inline void twoProduct(double a, double b, double& x, double& y)
{
    x = a * b;
    double ah, al, bh, bl;
    split(a, ah, al);
    split(b, bh, bl);
    y = al * bl - (((x - ah * bh) - al * bh) - ah * bl);
}

/// A real number as a sum of non-overlapping doubles in increasing magnitude, zeros removed: the
/// last component carries the sign. Grown one double at a time (Shewchuk's Grow-Expansion keeps
/// the components non-overlapping and ordered). The determinants here need at most 205.
class Expansion {
public:
    void add(double b)
    {
        double q = b;
        int k = 0;
        for (int i = 0; i < mSize; ++i) {
            double sum, err;
            twoSum(q, mTerm[i], sum, err);
            q = sum;
            if (err != 0.0) mTerm[k++] = err;
        }
        if (q != 0.0 || k == 0) {
            if (k == kCapacity) throw std::logic_error("predicates: expansion overflow");
            mTerm[k++] = q;
        }
        mSize = k;
    }
    void add(const Expansion& e, double sign = 1.0)
    {
        for (int i = 0; i < e.mSize; ++i) add(sign * e.mTerm[i]); // negation is exact
    }
    /// Adds the exact product e * f.
    void addProduct(const Expansion& e, const Expansion& f, double sign = 1.0)
    {
        for (int i = 0; i < e.mSize; ++i)
            for (int j = 0; j < f.mSize; ++j) {
                double x, y;
                twoProduct(e.mTerm[i], f.mTerm[j], x, y);
                add(sign * y);
                add(sign * x);
            }
    }
    int sign() const { return mSize == 0 ? 0 : (mTerm[mSize - 1] > 0) - (mTerm[mSize - 1] < 0); }

    /// a - b exactly.
    static Expansion difference(double a, double b)
    {
        Expansion e;
        double x, y;
        twoSum(a, -b, x, y);
        e.add(y);
        e.add(x);
        return e;
    }

private:
    static constexpr int kCapacity = 256;
    double mTerm[kCapacity];
    int mSize = 0;
};

/// p * q - r * s exactly.
Expansion crossTerm(const Expansion& p, const Expansion& q, const Expansion& r, const Expansion& s)
{
    Expansion e;
    e.addProduct(p, q);
    e.addProduct(r, s, -1.0);
    return e;
}

int sign(double x) { return (x > 0) - (x < 0); }

} // namespace

int orient2d(double ax, double ay, double bx, double by, double cx, double cy)
{
    const double left = (bx - ax) * (cy - ay), right = (by - ay) * (cx - ax);
    const double det = left - right;
    const double bound = kOrient2dBound * (std::abs(left) + std::abs(right));
    if (det > bound || -det > bound) return sign(det);
    if (left == 0.0 && right == 0.0) return 0; // both products exactly zero (no underflow at mesh scales)
    const Expansion ux = Expansion::difference(bx, ax), uy = Expansion::difference(by, ay);
    const Expansion vx = Expansion::difference(cx, ax), vy = Expansion::difference(cy, ay);
    return crossTerm(ux, vy, uy, vx).sign();
}

int orient3d(const double* a, const double* b, const double* c, const double* d)
{
    const double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
    const double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
    const double wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
    // (u x v) . w
    const double yz = uy * vz, zy = uz * vy, zx = uz * vx, xz = ux * vz, xy = ux * vy, yx = uy * vx;
    const double det = wx * (yz - zy) + wy * (zx - xz) + wz * (xy - yx);
    const double permanent = std::abs(wx) * (std::abs(yz) + std::abs(zy)) +
                             std::abs(wy) * (std::abs(zx) + std::abs(xz)) +
                             std::abs(wz) * (std::abs(xy) + std::abs(yx));
    const double bound = kOrient3dBound * permanent;
    if (det > bound || -det > bound) return sign(det);
    if (permanent == 0.0) return 0; // every product exactly zero (no underflow at mesh scales)
    const Expansion eux = Expansion::difference(b[0], a[0]), euy = Expansion::difference(b[1], a[1]),
                    euz = Expansion::difference(b[2], a[2]);
    const Expansion evx = Expansion::difference(c[0], a[0]), evy = Expansion::difference(c[1], a[1]),
                    evz = Expansion::difference(c[2], a[2]);
    const Expansion ewx = Expansion::difference(d[0], a[0]), ewy = Expansion::difference(d[1], a[1]),
                    ewz = Expansion::difference(d[2], a[2]);
    Expansion total;
    total.addProduct(ewx, crossTerm(euy, evz, euz, evy));
    total.addProduct(ewy, crossTerm(euz, evx, eux, evz));
    total.addProduct(ewz, crossTerm(eux, evy, euy, evx));
    return total.sign();
}

} // namespace riemesh::detail
