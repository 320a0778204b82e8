"""`make bench`: every benchmark, printed; never asserted in tests."""

from bench import (
    camera,
    camera_hand_eye,
    camera_images,
    evaluate,
    fit_floor,
    fleet,
    hand_eye_real,
    identify,
    identify_cost,
    identify_million,
    ik,
    import_rows,
    kinematics,
    montecarlo,
    peers,
    pose_sets,
    simulate,
)

if __name__ == "__main__":
    kinematics.main()
    print()
    robot3 = ik.controller()
    ik.main(robot3)
    print()
    peers.main(robot3)
    print()
    simulate.main()
    print()
    identify.main()
    print()
    pose_sets.main()
    print()
    identify_cost.main()
    print()
    identify_million.main(
        identify_million.ROWS, ten_files=False
    )  # ~10 min; skipped when memory is short
    print()
    fit_floor.main()
    print()
    camera.timing()  # the accuracy study: python -m bench.camera (minutes)
    print()
    camera_hand_eye.quick()  # the study: python -m bench.camera_hand_eye (~30 min)
    print()
    camera_images.quick()  # the study: python -m bench.camera_images (~11 minutes)
    print()
    hand_eye_real.main()
    print()
    evaluate.main()
    print()
    montecarlo.main()
    print()
    fleet.main()
    print()
    import_rows.quick()  # before/after: python -m bench.import_rows OTHER_ROOT
