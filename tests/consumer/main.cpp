// A minimal consumer of smg: includes the umbrella header and checks one round trip.
#include <smg/smg.hpp>

#include <cstdio>

int main() {
  const smg::Vector3<double> phi(0.1, 0.2, 0.3);
  const double err = (smg::so3::log(smg::so3::exp(phi)) - phi).norm();
  std::printf("smg %s consumer: |Log(Exp(phi)) - phi| = %.1e\n", SMG_VERSION_STRING, err);
  return err < 1e-12 ? 0 : 1;
}
