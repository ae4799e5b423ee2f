"""An FMU state carries its model, its build, its FMI version and an integrity seal: a state of
another model (in memory), of another build of the same model (serialized; a rebuilt FMU has
another instantiation token), of the FMI 2.0 build in the FMI 3.0 one, or a serialized state with
any one bit flipped is refused with Error (not OK and silently wrong, not Fatal) and a message
naming what does not match, and the instance runs on as if nothing happened.

References: an instance of the same FMU that was never handed the foreign state (its outputs, to
the bit), and the intact serialized bytes, which still restore.
"""
import contextlib
import io

import pytest

from support import DIST, Instance, fmu_path


def _fmi3(name):
    """An FMI 3.0 co-simulation instance of dist/fmi3/<name>.fmu through fmpy, initialized."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    path = DIST / "fmi3" / f"{name}.fmu"
    md = read_model_description(str(path))
    messages = []
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=f"{name}3")
    fmu.instantiate(loggingOn=True, logMessage=lambda env, status, cat, msg: messages.append((status, msg.decode())))
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu, messages


@pytest.mark.parametrize("own,foreign", [("PogoStick", "Penetrator"), ("PogoStickSMA", "HopController"),
                                         ("PogoStickSMA", "PogoStick")])
def test_another_models_state_is_refused_with_error_naming_both(own, foreign):
    """fmi2SetFMUstate with another model's in-memory state: Error (not OK and silently wrong, not
    Fatal), both models named, and the instance runs on as if nothing happened."""
    from fmpy.fmi1 import FMICallException

    a, b = Instance(own, "own").init(), Instance(foreign, "foreign").init()
    ref = Instance(own, "reference").init()
    try:
        b.run_to(0.5, 1e-3)
        st = b.fmu.getFMUstate()
        with pytest.raises(FMICallException) as exc:
            a.fmu.setFMUstate(st)
        assert "(error)" in str(exc.value)
        text = a.messages[-1][2]
        assert f"model '{foreign}'" in text and f"model '{own}'" in text and "refused" in text, text
        b.fmu.freeFMUstate(st)
        for inst in (a, ref):
            inst.run_to(1.0, 1e-3)
        assert a.outputs() == ref.outputs()
    finally:
        for inst in (a, b, ref):
            inst.close()


def test_another_builds_serialized_state_is_refused_naming_the_build(tmp_path):
    """Two builds of one model and FMI version (here: the session's and one with another token
    seed, as a rebuilt FMU would be) share names and variables but not their states: a state
    serialized by one is refused by the other with Error naming the build, and the instance runs on."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    from pogofmu import exporter as build

    with contextlib.redirect_stdout(io.StringIO()):
        other = build.build_one("PogoStick", tmp_path, token_seed="another build")
    md = read_model_description(str(other))
    assert md.guid != read_model_description(str(fmu_path("PogoStick"))).guid
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(other)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="other", fmiCallLogger=None)
    from support import fmi2_callbacks

    callbacks = fmi2_callbacks([])
    fmu.instantiate(loggingOn=True, callbacks=callbacks.struct)
    own = Instance("PogoStick", "own").init()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        own.run_to(0.3, 1e-3)
        blob = bytes(own.fmu.serializeFMUstate(own.fmu.getFMUstate()))
        with pytest.raises(FMICallException) as exc:
            fmu.deSerializeFMUstate(blob)
        assert "(error)" in str(exc.value)
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)  # still usable
        own_blob = bytes(fmu.serializeFMUstate(fmu.getFMUstate()))
        with pytest.raises(FMICallException):
            own.fmu.deSerializeFMUstate(own_blob)
        text = own.messages[-1][2]
        assert "build" in text and "refused" in text, text
    finally:
        own.close()
        fmu.terminate()
        fmu.freeInstance()


def test_fmi3_refuses_the_fmi2_builds_state_and_every_flipped_bit():
    """The FMI 2.0 and FMI 3.0 builds of one model share their code but not their states; a
    serialized FMI 3.0 state with any one bit flipped is refused as damaged (20 of 20), with
    Error, and the instance stays usable."""
    from fmpy.fmi1 import FMICallException

    two = Instance("PogoStick", "two").init()
    three, messages = _fmi3("PogoStick")
    try:
        two.run_to(0.3, 1e-3)
        blob2 = bytes(two.fmu.serializeFMUstate(two.fmu.getFMUstate()))
        with pytest.raises(Exception) as exc:
            three.deserializeFMUState(blob2)
        assert "error" in str(exc.value).lower()
        assert "FMI 2.0" in messages[-1][1] and "FMI 3.0" in messages[-1][1], messages[-1]
        three.doStep(0.0, 0.3)
        blob3 = bytes(three.serializeFMUState(three.getFMUState()))
        import random

        rng = random.Random(20)
        for _ in range(20):
            i = rng.randrange(len(blob3) * 8)
            flipped = bytearray(blob3)
            flipped[i // 8] ^= 1 << (i % 8)
            with pytest.raises(FMICallException) as exc:
                three.deserializeFMUState(bytes(flipped))
            assert "(error)" in str(exc.value)
            assert "damaged" in messages[-1][1] or "not a serialized pogofmu FMU state" in messages[-1][1], messages[-1]
        state = three.deserializeFMUState(blob3)  # the intact bytes still restore
        three.setFMUState(state)
        three.doStep(0.3, 0.1)
    finally:
        two.close()
        three.terminate()
        three.freeInstance()
