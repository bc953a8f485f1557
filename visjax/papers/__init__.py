"""One module per paper: its constants, published gains and numbers, its scenario (built
with `visjax.sim`), its experiment and metrics. Nothing outside knows a paper's numbers.

- `chitrakaran`: Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving object's
  velocity with a fixed camera* (the velocity estimator, section 6).
- `jang`: Jang's thesis on the structure of a moving point seen by a moving camera (the
  unknown input observer, seven experiment sets).
- `nath`: Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features
  using a moving uncalibrated camera* (the adaptive least-squares estimator).
"""

from . import chitrakaran as chitrakaran, jang as jang, nath as nath
