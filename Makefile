# ChefBot workspace. Every target runs `setup` first (idempotent, seconds when
# there is nothing to do). See README.md.
SHELL := /bin/bash
WITH_ENV := bash tools/with_env.sh

.PHONY: setup test demo bench soak shell lint clean help

help:
	@echo "make demo   - install what is missing, build, run the simulated delivery demo (headless without a display)"
	@echo "              another site: make demo WORLD=chefbot_sim/worlds/cafe.yaml MAP=chefbot_navigation/maps/cafe_map.yaml TABLES_FILE=chefbot_navigation/maps/cafe_tables.yaml"
	@echo "make demo SLAM=1 - book ch. 4 in one go: explore + map with our SLAM, save the map, localize on it (amcl), deliver"
	@echo "make demo ROBOTS=3 - three robots in one simulated hotel deliver at once (FLEET_FILE= for another site)"
	@echo "make test   - install what is missing, build, run every test; last line 'N passed, M failed'"
	@echo "make bench [K=SUBSTRING] - benchmarks (K: only the files whose path contains it): figures side by side,"
	@echo "              JSON in bench-results/, report docs/benchmarks.md (only the sections measured are replaced)"
	@echo "make soak [HOURS=2] [ROBOTS=3] [SEED=0] - the fleet soak: HOURS of sim time of orders, robot and dispatcher"
	@echo "              kills, batteries; JSON in bench-results/soak-*.json, report docs/soak.md (runs >= 1 h or REPORT=1)"
	@echo "make shell  - a bash with the workspace sourced (roslaunch/rosrun ready)"
	@echo "make setup  - only install and build"
	@echo "make lint   - ruff over the Python code"

setup:
	@bash tools/setup.sh

test: setup
	@$(WITH_ENV) python tools/run_tests.py

# make demo [WORLD=file.yaml|.world] [MAP=map.yaml] [TABLES_FILE=tables.yaml] [DRIVE=firmware|plugin] [GUI=0|1] [SLAM=1]
# ROBOTS=N (N >= 2): several robots in one world deliver at once [FLEET_FILE=site_fleet.yaml] (tools/fleet_demo.py)
# SLAM=1: map the world first (SLAM + explore), save, localize on the saved map, deliver; MAP= is then the
# world's raster, for judging the new map only
# (or CHEFBOT_DEMO_* variables)
demo: setup
	@$(if $(WORLD),CHEFBOT_DEMO_WORLD='$(WORLD)') $(if $(MAP),CHEFBOT_DEMO_MAP='$(MAP)') $(if $(DRIVE),CHEFBOT_DEMO_DRIVE='$(DRIVE)') \
	  $(if $(GUI),CHEFBOT_DEMO_GUI='$(GUI)') \
	  $(if $(SLAM),CHEFBOT_DEMO_SLAM='$(SLAM)') \
	  $(if $(ROBOTS),CHEFBOT_DEMO_ROBOTS='$(ROBOTS)') $(if $(FLEET_FILE),CHEFBOT_DEMO_FLEET_FILE='$(FLEET_FILE)') \
	  $(if $(TABLES_FILE),CHEFBOT_DEMO_TABLES_FILE='$(TABLES_FILE)') $(WITH_ENV) python tools/demo.py

# make bench [K=SUBSTRING]: every benchmark, or only the files whose path contains K (their report sections
# are replaced, the others kept: docs/testing.md)
bench: setup
	@$(WITH_ENV) python tools/bench.py $(if $(K),-k '$(K)')

# make soak [HOURS=2] [ROBOTS=3] [SEED=0] [REPORT=1]: the fleet soak test (tools/fleet_soak.py; not part of
# make test nor make bench). HOURS of sim time, fractional for a short check (HOURS=0.15); REPORT=1 writes
# docs/soak.md from a run under 1 h too
HOURS ?= 2
SEED ?= 0
soak: setup
	@$(WITH_ENV) python tools/fleet_soak.py --hours '$(HOURS)' --robots '$(or $(ROBOTS),3)' --seed '$(SEED)' \
	  $(if $(filter 1,$(REPORT)),--report)

lint: setup
	@$(WITH_ENV) ruff check .

shell: setup
	@bash --rcfile <(echo '[ -f ~/.bashrc ] && source ~/.bashrc; source tools/env.sh; PS1="(chefbot) $$PS1"') -i

clean:
	rm -rf build devel install CMakeLists.txt
