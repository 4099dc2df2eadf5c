"""Every wrong answer a sweep found, replayed: each must now name no false star.

The cases come from `python -m bench.bench_wrong` on the default database; the comment above
each group names the mechanism and the check that now refuses it.
"""

from __future__ import annotations

import pytest

from service.core.evaluate import score
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames

FOUND = [
    # (camera, noise px, false stars, mag noise, seed, frames, index)
    # session 4, `--frames 24000`; service/core/photometry.py (completeness). A false star fell
    # near a catalogue star fainter than the camera sees (the default set's deep member holds stars to 8 Mv) and was named.
    ("seed000", 0.25, 2, 0.3, 18019190785799434842, 200, 123),
    ("seed000", 0.25, 5, 0.0, 4463063595105581093, 200, 64),
    ("seed000", 0.25, 5, 0.3, 14285705283403074772, 200, 72),
    ("seed000", 1.0, 2, 0.3, 8938798499141819448, 200, 81),
    # session 5, `--frames 24000`; service/core/residuals.py. Each time the attitude was right and one
    # false star was named after a catalogue star: 1.9 px (7 sigma) from it inside the 2.5-px radius
    # floor at 0.25 px, or 2.4-3.5 sigma from a star at or past the camera's limit.
    ("seed001", 0.25, 5, 0.0, 393543455801370141, 200, 59),
    ("seed003", 0.25, 2, 0.3, 10315727423585640373, 200, 30),
    ("seed003", 2.0, 5, 0.0, 13318148164082012119, 200, 61),
    ("seed003", 2.0, 5, 0.3, 2272477347409813501, 200, 191),
    # session 6, `--frames 100000`; service/core/photometry.py (faintest_inverted). A false star
    # named after a catalogue star 0.06-0.45 mag fainter than every other pair, observed brighter
    # than 44-89 % of them.
    ("seed000", 1.0, 5, 0.0, 8251069352989427611, 833, 426),
    ("seed000", 2.0, 5, 0.0, 5205826470054889026, 833, 147),
    ("seed001", 1.0, 5, 0.3, 6427918992317128032, 833, 92),
    ("seed001", 2.0, 5, 0.0, 18085607491161595418, 833, 590),
    ("seed003", 1.0, 5, 0.3, 5678641243226933422, 833, 607),
    ("seed003", 2.0, 2, 0.0, 1270393800955699078, 833, 441),
    ("seed003", 2.0, 5, 0.0, 13318148164082012119, 833, 220),
    ("seed003", 2.0, 5, 0.0, 13318148164082012119, 833, 225),
    ("seed003", 2.0, 5, 0.0, 13318148164082012119, 833, 516),
    ("seed003", 2.0, 5, 0.0, 13318148164082012119, 833, 589),
    ("seed003", 2.0, 5, 0.3, 2272477347409813501, 833, 747),
    # session 8, `--frames 100000`; service/core/blends.py (RESOLVED_PX) and service/core/hidden.py.
    # Each time the attitude was right and one blob, 0.6-6 px from a 5.1-6.4 Mv star the frame's member
    # left out or that sat at the image border, was named as a brighter star 1.1-7 px away.
    ("seed003", 2.0, 2, 0.3, 10215180794168566637, 833, 790),
    ("seed003", 2.0, 5, 0.0, 13318148164082012119, 833, 519),
    ("seed004", 2.0, 0, 0.3, 9735585231734882535, 833, 434),
    ("seed004", 2.0, 2, 0.3, 11054696670007433002, 833, 643),
    ("seed004", 2.0, 5, 0.3, 4527235899829268017, 833, 182),
    ("seed004", 2.0, 5, 0.3, 4527235899829268017, 833, 530),
    # session 22, `--frames 20000 --seed 2`; service/core/hidden.py (the set's every star). A blob of
    # HIP 53100 (6.3 Mv), which both `wide` and the deep `narrow` member leave out (density caps)
    # and `sparse` holds, was named as HIP 53154 (5.3 Mv), predicted 3.5 px away past the image edge.
    ("seed004", 2.0, 0, 0.0, 13796341507166027222, 166, 86),
    # session 10's known wrong answer on seed 001 (below until session 22): since the default set's
    # `mid` member (V <= 6.5, the camera's own limit) serves seed 001's camera, the false star at the
    # camera's limit is no longer named (`mid` does not hold the 6.69-Mv star it was named after).
    ("seed001", 2.0, 5, 0.3, 11583023456393873584, 166, 37),
    # session 30, `--frames 100000 --seed 2`; service/core/photometry.py (faintest_inverted_among).
    # A false star named after a 6.35-Mv star (the camera sees to 6.0) outshone 7 of the 18 other
    # pairs, under the 40% that refuses it, but one of the 18 (4.8 Mv) was dropped by another check
    # in the same pass, which left the answer's faintest pair outshining 7 of 17.
    ("seed003", 2.0, 5, 0.0, 10667285709216991066, 833, 414),
    # session 32, known wrong answers of sessions 10 and 30 until then; service/core/photometry.py
    # (faintest_past_missed). The faintest pair's catalogue star lay past 2-24 of the field's stars
    # that went unseen between it and the next-faintest pair, in a frame whose stars show a sharp
    # limit: 13 false stars named after a star past the camera's limit, and a real star named after
    # a fainter neighbour.
    ("seed003", 2.0, 2, 0.3, 10215180794168566637, 166, 82),
    ("seed003", 2.0, 5, 0.0, 8928624839648508617, 833, 214),
    ("seed003", 2.0, 5, 0.0, 16161300031527355709, 833, 108),
    ("seed003", 1.0, 2, 0.0, 3435492181765054572, 833, 806),
    ("seed003", 2.0, 5, 0.3, 6049331707569415401, 833, 170),
    ("seed003", 2.0, 5, 0.3, 6049331707569415401, 833, 465),
    ("seed003", 2.0, 5, 0.3, 6049331707569415401, 833, 817),
    ("seed000", 1.0, 5, 0.0, 13910927852754925744, 833, 579),
    ("seed003", 2.0, 5, 0.0, 17531117374832281847, 833, 439),
    ("seed003", 1.0, 5, 0.0, 16134803790979173019, 833, 688),
    ("seed003", 2.0, 2, 0.3, 13280638366627353505, 833, 481),
    ("seed003", 2.0, 5, 0.3, 14714239795966869065, 833, 322),
    ("seed003", 2.0, 2, 0.3, 16902623796248992325, 833, 612),
    ("seed003", 2.0, 0, 0.3, 17193331164963438550, 833, 41),
    # session 33, `--frames 100000 --seed 12`; service/core/answer.py (repair_kernel). The verifier's
    # pairing was still growing at its last refit: a false star it had paired lay 7 px (220") off its
    # catalogue star under the final fit, which left 5 of the 14 real stars out; paired again from
    # that fit, the 14 real stars and no false one.
    ("seed000", 2.0, 2, 0.3, 4725724889438530113, 833, 785),
    # session 33, known wrong answers of session 30 until then; service/core/match.py (EDGE_CROWDS).
    # A real star's blob named after its neighbour 3.2-3.7 px away (363" and 265"), because its own
    # star was predicted a fraction of a pixel outside the image, where the pairing did not see it
    # crowd the blob.
    ("seed003", 2.0, 5, 0.0, 6509014638671384810, 833, 631),
    ("seed004", 2.0, 2, 0.3, 10829016878671831359, 833, 168),
    # session 40's known wrong answer, `--seed 13`; service/core/answer.py (field_stars_near) and
    # finish.py: EDGE_CROWDS in the close-double pairing. One blob for epsilon-1 and epsilon-2 Lyrae
    # (HIP 91919, 91926; 4.7 and 4.6 Mv, 4 px apart at 53"/px), labelled with the brighter, epsilon-2,
    # which the solved attitude predicted 0.25 px outside the 1024-px image: the close-double pairing
    # saw only the stars inside it and named the blob after epsilon-1. A star just past the edge now
    # crowds a blob there, as in the verifier's pairing, and the blob is left unnamed.
    ("seed003", 2.0, 0, 0.3, 10920456503512971860, 833, 243),
    # session 41, `--seed 21`; service/core/residuals.py (Z_OUTSIDE). Seed 000's camera at 0.5 px: a
    # false star 2.5 px (5 sigma) from HIP 110986 (5.5 Mv), which the final fit predicted 1.3 px
    # outside the image, was kept: the distance test saw only the pairs predicted inside.
    ("seed000", 0.5, 2, 0.3, 2277085313737080371, 833, 732),
    # and a known wrong answer of session 30 (`--seed 8`), of the same kind: a false star 4.9
    # px (2.45 sigma at 2 px) from a star predicted 0.4 px outside the image.
    ("seed004", 2.0, 5, 0.0, 14512514463542990805, 833, 478),
]


def _replayed(case, db):
    """The frame of a sweep's case (camera, noise px, false stars, mag noise, seed, frames, index),
    its score against the truth when solved (None when not), and the answer."""
    camera, noise, false, mag_noise, seed, n, index = case
    preset = PRESETS[camera]
    config = SimConfig(mag_limit=preset.mag_limit, centroid_noise_px=noise, false_stars=false, mag_noise=mag_noise)
    frame = simulate_frames(preset.camera, n, config, rng=seed)[index]
    sol = solve(frame.centroids, preset.camera, db, options=SolveOptions(centroid_sigma_px=noise))
    return (score(sol, frame.quaternion, frame.hip.tolist(), blends=frame.blends) if sol.solved else None), sol


@pytest.mark.parametrize("case", FOUND, ids=[f"{c[0]}-{c[1]}px-{c[2]}false-{c[6]}" for c in FOUND])
def test_found_wrong_answers_name_no_false_star(case, default_set_db) -> None:
    s, sol = _replayed(case, default_set_db)
    assert s is not None
    assert s.correct and s.wrong_stars == 0
    assert len(sol.stars) >= 8  # the real stars stay named


KNOWN_WRONG = [
    # sessions 10 and 30, `python -m bench.bench_wrong --frames 100000 --seed 4` to `--seed 9`: what is
    # left once faintest_past_missed refuses a faintest pair past unseen stars (14 moved to FOUND
    # above). Every one the right attitude with one star misnamed; no check built so far separates
    # them, kept here so that one that does shows (xfail is strict). 5: a false star named after a
    # catalogue star 0.01-0.4 mag past every other pair with 0-1 of the field's stars unseen
    # between (the band is that narrow), 0.5-5 px from it: as a real star at the limit would be.
    ("seed000", 2.0, 5, 0.3, 7949799409053215605, 833, 754),
    ("seed003", 2.0, 5, 0.3, 17557324495047974645, 833, 275),
    ("seed003", 1.0, 2, 0.0, 13904914547839974109, 833, 60),
    ("seed003", 1.0, 5, 0.3, 16392285237062196429, 833, 138),
    ("seed003", 2.0, 5, 0.0, 15795732165694557160, 833, 384),
    # 2 more past unseen stars (6-13 of them), where fewer than 90% of the field's stars in the 0.3
    # mag below the next-faintest pair are paired: the sharp limit the test asks for is not shown.
    ("seed003", 2.0, 5, 0.0, 16161300031527355709, 833, 525),
    ("seed003", 2.0, 5, 0.3, 14714239795966869065, 833, 598),
    # session 33, `--seed 11`: one more of that kind on seed 000's camera (0.3 mag of noise): a false
    # star named after a 7.18-Mv star, 0.7 mag past the next-faintest pair with 20 of the deep
    # member's stars unseen between, where 6 of the 7 stars in the 0.3 mag below that pair are paired
    # (86%). In a soft-limit model (`/work/s34/soft.py`: Hipparcos fields of 8-20 deg, a logistic
    # detection of width 0.05-0.3 mag) a real faintest star lies past 20 unseen stars in up to 62% of
    # frames, and lowering the gate to 80% doubles how often the real faintest star is refused.
    ("seed000", 2.0, 2, 0.3, 2358934478751642668, 833, 741),
    # 1 (2 until session 41, the other now in FOUND): a false star named after a catalogue star inside
    # the camera's limit, 3.2 px away. The star lies on the image's edge (predicted 0.2 px inside):
    # its own blob fell outside, and the false star is 1.6 sigma from the prediction, as a real blob
    # may be.
    ("seed000", 2.0, 5, 0.0, 1583350793573434237, 833, 229),
    # session 40, `--seed 14`: one more of that kind, in the image's corner: a false star at (20.6,
    # 2.9) px named after HIP 76669 (4.6 Mv), 3.2 px (171") from its prediction.
    ("seed003", 2.0, 5, 0.0, 3038708334197526774, 833, 560),
    # session 41, `--seed 15` and `--seed 16`: four more of the first kind on seed 003's camera at
    # 2 px (limit 6.0 Mv): a false star 2.5-4.0 px from a 6.01-6.27 Mv star, named after it, 0.01-0.27
    # mag past the next-faintest pair, with the attitude right and every other star named right.
    ("seed003", 2.0, 2, 0.0, 13727609920070369994, 833, 463),
    ("seed003", 2.0, 2, 0.0, 13727609920070369994, 833, 500),
    ("seed003", 2.0, 5, 0.0, 12292781523742250968, 833, 737),
    ("seed003", 2.0, 5, 0.3, 3965202615061329452, 833, 410),
    # session 41, `--seed 17` to `--seed 20`: five more of that kind, at 2 px with 2-5 false stars: a
    # false star 2.2-5.5 px from a star 0.03-0.22 mag past the next-faintest pair, at or past the
    # camera's limit (seed 003: 6.00-6.14 Mv; seed 000: 6.52), the attitude right (a sparse frame of
    # seed 002 of the same kind: KNOWN_WRONG_SPARSE).
    ("seed003", 2.0, 5, 0.0, 6775631048045252321, 833, 108),
    ("seed003", 2.0, 2, 0.0, 7781357002542514233, 833, 660),
    ("seed003", 2.0, 5, 0.3, 6075573368267747078, 833, 390),
    ("seed000", 2.0, 5, 0.3, 4292089354677280753, 833, 280),
    # and two of the edge kind on seed 004's camera (2 px, 5 false stars): the star's own blob pushed
    # outside the image by the noise, a false star 2.5-3.2 px from its prediction (1021.1 px inside,
    # 1024.1 px just outside under the final fit) named after it: HIP 33160 (4.0 Mv, observed 1.0 mag
    # fainter) and HIP 36251 (5.8 Mv, 0.4 mag fainter).
    ("seed004", 2.0, 5, 0.0, 15885676424625814845, 833, 431),
    ("seed004", 2.0, 5, 0.0, 7854512143107319413, 833, 355),
    # session 41, `--seed 22` and `--seed 23`: two more of the first kind at 2 px: a false star 1.7 and
    # 3.7 px from a 6.36-Mv star (seed 003, 0.37 mag past the next-faintest pair) and a 6.45-Mv one
    # (seed 000, at its 6.5 limit, 0.04 past).
    ("seed003", 2.0, 5, 0.0, 2346366075819820453, 833, 592),
    ("seed000", 2.0, 2, 0.3, 1471650040241400341, 833, 460),
]


@pytest.mark.xfail(reason="one star misnamed under the right attitude: a false star at the camera's limit or near a "
                          "faint star (sessions 10, 30, 32, 33, 40, 41)")
@pytest.mark.parametrize("case", KNOWN_WRONG, ids=[f"{c[0]}-{c[1]}px-{c[2]}false-{c[6]}" for c in KNOWN_WRONG])
def test_known_wrong_answers_at_the_limit(case, default_set_db) -> None:
    test_found_wrong_answers_name_no_false_star(case, default_set_db)


KNOWN_WRONG_SPARSE = [
    # session 41, `--seed 20`: seed 002's camera (4 deg, limit 7.0 Mv) at 2 px with 5 false stars, a
    # 9-centroid frame answered by maxangle with 5 stars, one of them a false star 4.6 px from a
    # 7.31-Mv star (0.35 mag past the next-faintest pair), the attitude right. Too few stars for the
    # 8 the test above asks to stay named: here an answer without the false star, or none, passes.
    ("seed002", 2.0, 5, 0.0, 12399234289052669444, 833, 607),
    # `--seed 23`: the same camera at 2 px with 5 false stars and 0.3 mag of noise, 5 stars named by
    # maxangle, one a false star 2.2 px from HIP 80057 (5.2 Mv), whose light the simulator merged
    # into its neighbour HIP 80047's blob 29 px away (its blend radius is in degrees, ~100" here).
    ("seed002", 2.0, 5, 0.3, 16465620553203262906, 833, 414),
]


@pytest.mark.xfail(reason="a false star named in a sparse frame (session 41)")
@pytest.mark.parametrize("case", KNOWN_WRONG_SPARSE, ids=[f"{c[0]}-{c[1]}px-{c[2]}false-{c[6]}" for c in KNOWN_WRONG_SPARSE])
def test_known_wrong_answers_of_sparse_frames(case, default_set_db) -> None:
    s, _ = _replayed(case, default_set_db)
    assert s is None or (s.correct and s.wrong_stars == 0)
