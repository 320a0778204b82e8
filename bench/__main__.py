"""`make bench`: every benchmark, printed; never asserted in tests."""

from bench import evaluate, fleet, identify, ik, kinematics, montecarlo, simulate

if __name__ == "__main__":
    kinematics.main()
    print()
    ik.main()
    print()
    simulate.main()
    print()
    identify.main()
    print()
    evaluate.main()
    print()
    montecarlo.main()
    print()
    fleet.main()
