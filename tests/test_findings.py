"""One view's measurement findings as one typed record (:mod:`nerif.sensing.findings`): what it reports, what it reads
back."""
import json

from nerif.sensing.findings import Findings


def test_the_report_holds_every_finding_of_the_stage_and_a_captures_own_only_where_set():
    stage = Findings(saturated=0.01, occluded=0.0, unmeasured=0.0, rejected=0.002, shake_px=[0.1, -0.2],
                     normalise_px=None, noise=0.004)
    report = stage.report()
    assert report["normalise_px"] is None and report["shake_px"] == [0.1, -0.2]  # the stage's, set or not
    assert not {"from_cache", "exposures", "image_noise", "reference_noise"} & set(report)  # a capture's, unset
    stage.from_cache, stage.exposures = True, [3, 1]  # a capture sets its four together, None where one exposure
    assert stage.report()["from_cache"] is True and stage.report()["exposures"] == [3, 1]
    assert stage.report()["image_noise"] is None and "image_noise" in stage.report()


def test_a_cached_report_reads_back_to_the_same_record_and_unknown_names_are_left_out():
    found = Findings(difference_rms=0.05, texture_ratio=0.97, flow_factor=2, clipped=0.0, valid_fraction=0.91,
                     shake_px=[0.0, 0.3], outside_px=None, noise=0.01, from_cache=False)
    back = Findings.read(json.loads(json.dumps(found.report())))
    assert back == found
    assert Findings.read({"noise": 0.02, "a_finding_of_another_nerif": 1}) == Findings(noise=0.02)
