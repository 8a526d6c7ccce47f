"""``check_lift_server``: serves ``/check_lift`` (dam_interfaces/srv/CheckLift) from the core.

Run it with ``ros2 run dam_analysis check_lift_server [--ros-args --params-file p.yaml]``.

Parameters
----------
config_file : string, read-only
    The DAM configuration file; empty means the installed ``config/dam.yaml`` (or ``DAM_CONFIG``).
config_overlay : string, read-only
    A YAML file with part of a configuration merged over it, e.g. the overlay written by
    ``calibrate_csm`` (``docs/analysis.md``); empty means none.
default_friction_angle : double [rad], in [0, pi/2)
    Friction angle used when a request's ``friction_angle`` is negative. Defaults to the
    configured ``contact.friction_angle_deg``. May be changed at run time.

Request fields left out mean "use the configuration" (``dam_interfaces/srv/CheckLift``):
an empty ``k_theta`` is the configured ``task.k_theta_nm_per_rad`` (finger 1, the others from
the ratios), an empty ``delta_theta_p`` the configured ``task.delta_theta_p_deg`` for every
finger, a negative ``friction_angle`` (the default, -1) ``default_friction_angle``. So a
default-constructed request asks about the configured task pair at the configured friction
angle; the answer's message says which values came from the configuration.

Only a malformed request gets ``ok = false``, with a message that names the field and the
value (angles in rad and deg, 4 significant digits: ``delta_theta_p: [1.396] rad ([80] deg)
exceeds delta_theta_p_max 1.134 rad (65 deg)``), and every number of the answer NaN (the
margins too); the server never dies on input. A well-formed pair beyond the end of the SPCM branch
(eqs. 1-4 have no solution there) is answered ``ok = true`` with "no lift": both lift flags
false, both margins NaN, NaN per-finger values for the fingers beyond, and a message naming
where (deg) and why the branch ends.

The same node serves ``/plan_lift`` (dam_interfaces/srv/PlanLift): the robust pair over ranges
of friction angle, mass and object position (:mod:`dam_analysis.planner`); its fields left out
mean the configured values too. The first request with a position tolerance builds an analysis
per position node (about 0.5 s each, kept); later ones take a few tenths of a second. Plans run
on a thread of their own, one at a time, so ``/check_lift`` answers meanwhile; the node's one
executor thread only takes requests and sends answers (a multi-threaded executor would cost
every ``/check_lift`` round trip about 0.2 ms more).

Both services answer for a column object of the configuration's ``object.library`` named in
the request's ``object`` field (empty: ``object.default``); the analysis of each object is
built on its first request (about half a second) and kept. An unknown name, or an object the
fingers make no first contact with, is a malformed request naming it.

Every answer also says what the analysis assumes of the hand (:mod:`dam_analysis.hand_limits`):
``torque_limit`` and ``within_torque_limit`` (a pair guaranteed by eq. 18 whose ``tau_s``
exceeds what the hand gives is, the message says, "guaranteed by eq. 18 but not for this
hand"), and ``csm_penetration`` and ``csm_in_domain`` (the contact stiffness model's answer
is not to be trusted where its contact penetration leaves the configured bound).
"""

from __future__ import annotations

import array
import dataclasses
import math
import threading
from collections.abc import Callable
from typing import TypeVar

from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future

from dam_analysis.analysis import LiftAnalyzer, unreachable_object
from dam_analysis.errors import DamAnalysisError, InputError, NoSolutionError
from dam_analysis.hand_limits import limit_notes
from dam_analysis.planner import LiftPlanner, PlanResult, plan_verdict, ranges_from_request
from dam_common.config import DamConfig, load_config
from dam_common.echo import brief_repr, brief_text
from dam_common.errors import ConfigError
from dam_common.node import declare_config_file, declare_config_overlay, run_node
from dam_common.service_qos import SERVICE_QOS
from dam_common.shutdown import SHUTDOWN
from dam_interfaces.srv import CheckLift, PlanLift

_MAX_FRICTION_ANGLE = math.pi / 2
T = TypeVar('T')


class CheckLiftServer(Node):
    """Answers CheckLift requests with the sufficient condition and the contact stiffness model."""

    def __init__(self) -> None:
        super().__init__('check_lift_server')
        config_file = declare_config_file(self)
        overlays = declare_config_overlay(self)
        self._config = load_config(config_file or None, overlays)
        #: one analysis per object, built on its first request (each executor thread keeps
        #: its own: /check_lift's analyzers and /plan_lift's planners share nothing)
        self._analyzers: dict[str, LiftAnalyzer | InputError] = {
            self._config.object.name: LiftAnalyzer(self._config).build()}
        self._planners: dict[str, LiftPlanner | InputError] = {}
        self._default_friction_angle = self._config.contact.friction_angle_rad
        self.declare_parameter(
            'default_friction_angle', self._default_friction_angle,
            ParameterDescriptor(
                description='friction angle alpha [rad] used when a request gives a negative one',
                floating_point_range=[FloatingPointRange(
                    from_value=0.0, to_value=_MAX_FRICTION_ANGLE - 1e-9, step=0.0)]))
        self._default_friction_angle = float(
            self.get_parameter('default_friction_angle').value)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._service = self.create_service(CheckLift, 'check_lift', self._on_request,
                                            qos_profile=SERVICE_QOS)
        # /plan_lift's work on a thread of its own (_on_plan awaits it): a first plan with a
        # new position tolerance takes seconds, and /check_lift goes on answering meanwhile.
        # The planner keeps analyses of its own, so the threads share no mutable state; plans
        # run one at a time. The service is in a callback group of its own: a callback group
        # counts as busy until its coroutine is done, and /check_lift's must not be.
        self._planners[self._config.object.name] = LiftPlanner(self._config)
        self._planning = threading.Lock()
        self._plan_service = self.create_service(
            PlanLift, 'plan_lift', self._on_plan, qos_profile=SERVICE_QOS,
            callback_group=MutuallyExclusiveCallbackGroup())
        self.get_logger().info(
            f'serving {self._service.srv_name} and {self._plan_service.srv_name} with '
            f'{self._config.source} (objects: {", ".join(sorted(self._config.objects))}; default '
            f'{self._config.object.name}; default friction angle '
            f'{math.degrees(self._default_friction_angle):.3g} deg)')

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for param in params:
            if param.name == 'default_friction_angle':
                value = param.value
                if not isinstance(value, float) or not math.isfinite(value) \
                        or not 0.0 <= value < _MAX_FRICTION_ANGLE:
                    return SetParametersResult(
                        successful=False,
                        reason=f'default_friction_angle must be in [0, pi/2) rad, got '
                               f'{brief_repr(value)}')
        for param in params:
            if param.name == 'default_friction_angle':
                self._default_friction_angle = float(param.value)
        return SetParametersResult(successful=True)

    def _on_request(self, request: CheckLift.Request,
                    response: CheckLift.Response) -> CheckLift.Response:
        task = self._config.task
        k_theta = list(request.k_theta)
        delta_theta_p = list(request.delta_theta_p)
        friction_angle = float(request.friction_angle)
        response.friction_angle = math.nan  # until an answer is computed: a rejected answer's
        response.torque_limit = math.nan  # numbers are NaN (0.0 would read "on the boundary")
        response.worst_case_margin = response.csm_margin = math.nan
        response.rolling_margin = response.rolling_turn = response.rolling_slide = math.nan
        response.csm_path_margin = response.csm_path_delta_theta_p = math.nan
        defaults: list[str] = []
        name = request.object or self._config.object.name
        analyzer = self._computed(response, 'preparing the object',
                                  lambda: self._cached(self._analyzers, name, LiftAnalyzer))
        if analyzer is None:
            return response
        response.object = name
        if not k_theta:
            k_theta = [task.k_theta_nm_per_rad]
            defaults.append(f'k_theta = {task.k_theta_nm_per_rad:g} N*m/rad')
        if not delta_theta_p:
            delta_theta_p = [task.delta_theta_p_rad]
            defaults.append(f'delta_theta_p = {math.degrees(task.delta_theta_p_rad):g} deg')
        if math.isfinite(friction_angle) and friction_angle < 0.0:
            friction_angle = self._default_friction_angle  # NaN/inf: rejected by the core
            defaults.append(f'friction_angle = {math.degrees(friction_angle):.4g} deg')
        result = self._computed(
            response, 'analysing the request',
            lambda: analyzer.check_lift(k_theta, delta_theta_p, friction_angle))
        if result is None:
            return response
        response.ok = True
        response.friction_angle = friction_angle
        response.lift_guaranteed = bool(result.lift_guaranteed)
        response.worst_case_margin = float(result.worst_case_margin)
        response.csm_lift = bool(result.csm_lift)
        response.csm_margin = float(result.csm_margin)
        # array.array('d') is taken as is by the generated setters (no per-element checks)
        response.delta_theta_s = array.array('d', result.delta_theta_s)
        response.compliant_torque = array.array('d', result.compliant_torque)
        response.torque_limit = float(result.torque_limit)
        response.within_torque_limit = bool(result.within_torque_limit)
        response.csm_penetration = array.array('d', result.csm_penetration)
        response.csm_in_domain = bool(result.csm_in_domain)
        response.rolling_checked = bool(result.rolling_checked)
        response.rolling_margin = float(result.rolling_margin)
        response.rolling_turn = float(result.rolling_turn)
        response.rolling_slide = float(result.rolling_slide)
        response.csm_path_lift = bool(result.csm_path_lift)
        response.csm_path_margin = float(result.csm_path_margin)
        response.csm_path_delta_theta_p = float(result.csm_path_delta_theta_p)
        if result.branch_message:
            message = result.branch_message
        elif result.rolling_message:
            message = ('lift not guaranteed: eq. 18 holds at rest '
                       f'({result.worst_case_margin:+.4g} N), but {result.rolling_message}')
        elif result.lift_guaranteed and result.rolling_checked:
            message = ('lift guaranteed (eq. 18, and the object can rest in none of the poses '
                       'it can turn into on the table)')
        elif result.lift_guaranteed:
            message = 'lift guaranteed (eq. 18)'
        else:
            message = 'lift not guaranteed for every admissible contact force'
        notes = limit_notes(analyzer.limits, response.compliant_torque,
                            response.lift_guaranteed, response.csm_penetration,
                            response.csm_lift)
        if notes:
            message += '; ' + '; '.join(notes)
        defaults += self._object_note(request.object)
        if defaults:
            message += f' [from the configuration: {", ".join(defaults)}]'
        response.message = message
        return response

    def _object_note(self, requested: str) -> list[str]:
        """The note for the message's values from the configuration: the default object when
        the request names none (last in the list)."""
        return [] if requested else [f'object = {self._config.object.name}']

    def _cached(self, cache: dict[str, T | InputError], name: str,
                build: Callable[[DamConfig], T]) -> T:
        """``cache[name]``, built from the configuration with that object on first use (an
        object the fingers cannot reach is remembered too: no rebuild on every request).

        Raises
        ------
        InputError
            ``name`` is not in the object library, or the fingers reach no first contact
            with the object (the message names it).
        """
        if name not in cache:
            try:
                config = self._config.with_object(name)
            except ConfigError as exc:  # names the object and the library
                raise InputError(str(exc)) from exc
            try:
                cache[name] = build(config)
            except NoSolutionError as exc:
                cache[name] = InputError(unreachable_object(config, exc))
            else:
                self.get_logger().info(f'analysis of object {name!r} '
                                       f'({config.object.section.describe()}) ready')
        answer = cache[name]
        if isinstance(answer, InputError):
            raise InputError(str(answer))
        return answer

    def _computed(self, response: CheckLift.Response | PlanLift.Response, doing: str,
                  compute: Callable[[], T]) -> T | None:
        """``compute()``, or None with ``response.ok`` false and the reason in its message: a
        malformed request (the core's error names the field and the value) or, so that the
        server stays up whatever happens, any other error."""
        try:
            return compute()
        except DamAnalysisError as exc:
            response.ok = False
            response.message = brief_text(str(exc))  # quotes of the request are cut already
            self.get_logger().warning(f'rejected request ({doing}): {response.message}')
        except Exception as exc:  # noqa: BLE001 - the server must stay up whatever happens
            response.ok = False
            response.message = brief_text(f'internal error while {doing}: {exc!r}')
            self.get_logger().error(response.message)
        return None

    async def _on_plan(self, request: PlanLift.Request, response: PlanLift.Response
                       ) -> PlanLift.Response:
        """Plan on a thread of its own and answer when it is done; the executor thread serves
        ``/check_lift`` meanwhile."""
        done: Future = Future(executor=self.executor)
        # A done callback makes the executor wake up (and resume this coroutine) when the
        # plan's thread sets the result.
        done.add_done_callback(lambda _future: None)

        def work() -> None:
            try:
                done.set_result(self._plan(request, response))
            except BaseException as exc:  # noqa: BLE001 - re-raised in the executor
                done.set_exception(exc)

        threading.Thread(target=work, name='plan_lift', daemon=True).start()
        return await done

    def _plan(self, request: PlanLift.Request, response: PlanLift.Response
              ) -> PlanLift.Response:
        for name in _PLAN_NUMBERS:  # NaN until a plan says otherwise
            setattr(response, name, math.nan)
        object_name = request.object or self._config.object.name

        def compute() -> tuple[PlanResult, list[str]]:
            planner = self._cached(self._planners, object_name, LiftPlanner)
            ranges, from_config = ranges_from_request(
                planner, request.friction_angle_min, request.friction_angle_max,
                request.mass_min, request.mass_max, request.position_tolerance,
                request.k_theta_max, request.delta_theta_p_min, request.delta_theta_p_max,
                request.min_margin)
            return planner.plan(ranges, stop=lambda: SHUTDOWN.requested), from_config

        with self._planning:
            answer = self._computed(response, 'planning', compute)
        if answer is None:
            return response
        plan, from_config = answer
        taken = from_config + self._object_note(request.object)
        response.ok = True
        response.object = object_name
        _fill_plan(response, plan)
        message = plan_verdict(plan)
        if taken:
            message += f' [from the configuration: {", ".join(taken)}]'
        response.message = message
        return response


    def destroy_node(self) -> None:
        """Let a running plan end first: it stops at its next position node once the stop is
        requested (0.5 s at most), so no thread answers on a destroyed service."""
        if self._planning.acquire(timeout=2.0):
            self._planning.release()
        super().destroy_node()


#: The fields a PlanResult shares with PlanLift.Response (its other two, ``reason`` and
#: ``offsets``, go into the message or nowhere), and those of them that are numbers.
_PLAN_FIELDS = tuple(f.name for f in dataclasses.fields(PlanResult)
                     if f.name in PlanLift.Response.get_fields_and_field_types())
_PLAN_NUMBERS = tuple(name for name in _PLAN_FIELDS
                      if PlanLift.Response.get_fields_and_field_types()[name] == 'double')


def _fill_plan(response: PlanLift.Response, plan: PlanResult) -> None:
    for name in _PLAN_FIELDS:
        value = getattr(plan, name)
        setattr(response, name, float(value) if name in _PLAN_NUMBERS else value)


def main(args: list[str] | None = None) -> None:
    run_node(CheckLiftServer, 'check_lift_server', args, startup_errors=(DamAnalysisError,))


if __name__ == '__main__':
    main()
