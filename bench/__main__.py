"""`make bench`: every benchmark, printed; never asserted in tests."""

from bench import identify, ik, kinematics, simulate

if __name__ == "__main__":
    kinematics.main()
    print()
    ik.main()
    print()
    simulate.main()
    print()
    identify.main()
