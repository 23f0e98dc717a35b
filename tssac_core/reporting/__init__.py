"""What the commands show people: ``plots`` (figures 7 and 8 of a run, figure 9 of a mission), ``mission_animation``
(``fly --animate``: a mission as a film) and ``progress`` (the bars of long work, with the time left of missions
flown at once)."""
