"""Write the seed corpus of the fuzz targets (tests/fuzz/corpus/<target>/): a few programs that reach deep into
each interface (initialised, stepping, Model Exchange modes, state round trips), from which libFuzzer mutates.
The byte layout is fuzz_native.c's / fuzz_layer.c's reading order (an exhausted input reads as zeros).

    python3 tests/fuzz/seeds.py
"""
from __future__ import annotations

import hashlib
from pathlib import Path

HERE = Path(__file__).resolve().parent
MODELS = ("HertzEAOscillator", "AdaptiveLyapunovController", "HertzEAClosedLoop")

# fmi2_op / fmi3_op numbers (the `switch (op % N)` cases)
SETUP = [0, 0, 0, 0, 0, 0]  # FMI 2 SetupExperiment / FMI 3 EnterInitializationMode, defaults
STEP2 = [3, 0, 2, 0]        # fmi2DoStep at the current time, h = 0.1
STEP3 = [4, 0, 2, 0, 0, 0]  # fmi3DoStep at the current time, h = 0.1, no NULL outputs
ALL2, ALL3 = [39], [43]     # read every Real

CALLS = {
    "fmi2_cs_run": [0, 0, *SETUP, 1, 2, *STEP2 * 5, *ALL2],
    "fmi2_cs_state": [0, 0, *SETUP, 1, 2, *STEP2, 17, 0, *STEP2, 20, 0, 0, 1, 18, 1, *STEP2, *ALL2],
    "fmi2_cs_bad_step": [0, 0, *SETUP, 1, 2, 3, 0, 8, 0, 22, *SETUP, 1, 2, *STEP2, *ALL2],
    "fmi2_me_run": [0, 1, *SETUP, 1, 2, 29, 1, 30, 32, 0, 2, 34, 0, 1, 35, 0, 1, 36, 0, 1, 31, 0, 0, 28, *ALL2],
    "fmi3_cs_run": [1, 0, *SETUP, 1, *STEP3 * 5, *ALL3],
    "fmi3_cs_events": [1, 0x12, *SETUP, 1, 25, 16, 3, *STEP3 * 5, 2, 25, 16, 3, *STEP3, *ALL3],
    "fmi3_cs_state": [1, 0, *SETUP, 1, *STEP3, 18, 0, *STEP3, 21, 0, 0, 1, 19, 1, *STEP3, *ALL3],
    "fmi3_me_run": [1, 1, *SETUP, 1, 25, 16, 28, 30, 0, 2, 32, 0, 1, 33, 0, 1, 34, 0, 1, 29, 0, 0, 2, *ALL3],
    # a campaign's timeout (round 10): a doStep of h = 3.7e-6 from a host time within 1e-9 relative of the plant's at
    # tau = 3e296 but not equal to it (an ulp there is 4e280): RK4 was asked for more than 1e280 steps of 0.01 to
    # catch up (the catch-up plant_t .. t + h is now bounded as h is: settings.check_step, plant.c's check_step_with)
    "fmi2_cs_far_catch_up": bytes.fromhex(
        "fab8b80112b8b8b81bae00327d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d000052000c0c0c1c0c0c0c0c4c"
        "310c160c0100012902053a7d7d7d7d7d7d7d7d7d7d7d7d00047d012902053a7d7d7d7d7d7d7d7d7dffffff61030303ff"
        "fcfcfc7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d"
        "7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d7d03037d03030303037d7d"),
}
# state: how (bit 0 FMI 3, bit 1 ME), steps, number of patches - 1, then patches (kind, offset u16, argument)
NAN_K, INF_K = 18, 19  # fuzz_input.h INTERESTING[]: NAN, INFINITY
STATE: dict[str, list[int] | bytes] = {
    "fmi2_cs_nan": [0, 2, 0, 1, 88, 0, NAN_K, *ALL2],
    "fmi2_me_x": [2, 2, 0, 1, 80, 0, 8, *ALL2],
    "fmi2_cs_flip": [0, 3, 1, 3, 0x40, 1, 5, 2, 0x20, 1, 21, 1],
    "fmi3_cs_mode": [1, 2, 0, 0, 0, 0, 7, 3, 0, 0, 0, 0, 0, 0, 0, *ALL3],
    "fmi3_me_inf": [3, 2, 0, 1, 120, 0, INF_K],
    "fmi2_fresh": [0, 0, 0, 0, 100, 0, 4, 255],
    # a campaign's timeout (round 8): a patched state whose next step has x'' ~ 1e46, where the event search
    # walked 2^40 pieces (integrate.EVENT_ROUNDING now bounds it)
    "fmi2_cs_event_hull": [0x00, 0x02, 0x00, 0x00, 0xF7, 0x00, 0x76, 0x4F, 0x72, 0x65, 0x66, 0x12, 0xA9, 0x42],
    # a campaign's crash (round 9): an FMI 3 state restored before initialisation (model.built = 0) with patched
    # model bytes, then an event indicator read through fmi3GetFloat64: the indicators read the unbuilt model's
    # solver dimension (5.9e17) and indexed past its arrays (model_me_indicators now reads no unbuilt model)
    "fmi3_cs_unbuilt": bytes.fromhex("1d0806060606060606060606067a060606060606060606060606f6f600f606060606060606f6f600"
                                     "f68f4b30089cff60706000b47a8f4b30089cff066050656060"),
    # a campaign's finding (round 11): a closed loop's Model Exchange state restored, then SetContinuousStates with
    # x = 1.8e308 (finite, so taken) and GetEventIndicators: the contact indicator 1 + 2x/3 overflowed to inf, answered
    # with OK (fmi2_me.c's fmi2GetEventIndicators now refuses a non-finite indicator, as fmi2GetDerivatives does)
    "fmi2_me_beyond_range": bytes.fromhex("020208fff821212127114f4f4f4f4f4f4f4f4f4f4f3b4f000000253535353527113131204f4f4f23"
                                          "4f4f4f4f4f4f4f4f4f4f4f05352711"),
}
LAYER = {
    "uri": [0, 200, 3, 5, *b"/tmp"],
    "instantiate": [1, 4, *b"name", 1, 1, 4, *b"guid", 3, 4, *b"/tmp", 1, 0, 1, 100],
    "logging": [2, 4, *b"name", 1, 0, 1, 3, 0, 5, *b"lo%gX", 1, 2, 0, 5, *b"%s%d", 4, *b"cat%", 3, 7],
}


def write(folder: Path, programs: dict[str, list[int] | bytes]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, program in programs.items():
        data = bytes(program)
        (folder / f"{name}-{hashlib.sha1(data).hexdigest()[:8]}").write_bytes(data)


def write_all(root: Path) -> None:
    """The seed corpus under root/<target>/."""
    for model in MODELS:
        write(root / f"calls_{model}", CALLS)
        write(root / f"state_{model}", STATE)
    write(root / "layer", LAYER)


def main() -> None:
    write_all(HERE / "corpus")
    print("seeds written under", HERE / "corpus")


if __name__ == "__main__":
    main()
