"""Assignments instructors can generate and grade reproducibly (issue 11).

One module per job:

* :mod:`.template`   the assignment template (base system, hidden-effect families and sizes, rubric)
* :mod:`.roster`     the class roster (id, name, optional email)
* :mod:`.make`       ``sysid assignment make``: one record + starter config per student, the key
* :mod:`.submission` the documented submission format (``config.yaml`` + ``answer.yaml``), validated
* :mod:`.rubric`     the score from the rubric weights of the template
* :mod:`.grade`      ``sysid grade``: re-runs every submission, writes the gradebook
* :mod:`.summary`    the instructor's summary page (self-contained HTML)
* :mod:`.solution`   the reference extended config of a student's hidden effect (solutions, tests, bench)
* :mod:`.cli`        the two commands, registered through ``pipeline.cli.COMMAND_MODULES``
"""

KEY_SCHEMA = "sysid-assignment-key/1"
