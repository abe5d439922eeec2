"""Hardware in the loop with a rendered target (``docs/hil.md``): the impact protocol on a
carrier robot that renders the target's free flight, its recording, and what
``ffexp analyze`` reports of it (the apparent restitution, the loop's delay) beside the
delayed unilateral contact it should follow (:mod:`ffexp.hil.reference`)."""
