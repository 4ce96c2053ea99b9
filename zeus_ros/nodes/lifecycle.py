"""Managed (lifecycle) nodes: the transitions as four small methods, and `autostart`.

Why: ROS tooling (`ros2 lifecycle`, nav2's lifecycle_manager) brings managed nodes up step by
step: configure loads what the node needs (its checkpoint), activate makes it act, deactivate
stops it acting without a restart, cleanup lets go of what configure took. `autostart`
(default true, like nav2's lifecycle_manager) configures and activates the node while it is
built, so `ros2 run`, both launchers and the tests see a node that acts from the start; a
configure that fails then stops the process with its one line (exit 2) as before. With
`autostart:=false` the node comes up unconfigured and waits for
`ros2 lifecycle set /policy configure` and `... activate`; a failed configure is one ERROR line
and the transition's FAILURE, the node stays unconfigured.
"""

from __future__ import annotations

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from zeus_ros.nodes.params import Spec

__all__ = ['LIFECYCLE_SPECS', 'ManagedNode']

LIFECYCLE_SPECS: dict[str, Spec] = {
    'autostart': Spec(True, 'configure and activate at start (false: the node comes up '
                      'unconfigured and waits for `ros2 lifecycle set <node> configure`, then '
                      '`activate`; docs/usage.md)'),
}
SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE


class ManagedNode(LifecycleNode):
    """A LifecycleNode; a subclass fills in `_configure`, `_release`, `_activate`, `_deactivate`.

    `configured` and `active` say where the node is; callbacks check `active` before acting.
    """

    configured = False
    active = False
    _autostarting = False
    _configure_error: BaseException | None = None

    def _configure(self) -> None:
        """Load the checkpoint and build the data path; raise (ValueError: one line) to fail."""
        raise NotImplementedError

    def _release(self) -> None:
        """Let go of what `_configure` took (also after a half-done one)."""
        raise NotImplementedError

    def _activate(self) -> None:
        """Start acting."""

    def _deactivate(self) -> None:
        """Stop acting (the node stays configured)."""

    def autostart(self, enabled: bool) -> None:
        """Configure and activate now (`autostart`); a configure error is raised as it came."""
        if not enabled:
            self.get_logger().info(
                'unconfigured (autostart:=false): waiting for `ros2 lifecycle set '
                f'{self.get_fully_qualified_name()} configure`, then `activate`')
            return
        self._autostarting, self._configure_error = True, None
        try:
            if self.trigger_configure() != SUCCESS:
                raise self._configure_error or RuntimeError(
                    f'{self.get_name()}: configure failed')
            if self.trigger_activate() != SUCCESS:
                raise RuntimeError(f'{self.get_name()}: activate failed')
        finally:
            self._autostarting = False

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load and build; an error is FAILURE (raised by autostart, else one ERROR line)."""
        try:
            self._configure()
        except Exception as error:  # rclpy would turn it into a silent ERROR transition
            self._configure_error = error
            self._release()
            if not self._autostarting:
                kind = '' if isinstance(error, ValueError) else f'{type(error).__name__}: '
                self.get_logger().error(f'configure failed: {kind}{error}')
            return FAILURE
        self.configured = True
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Act from now on."""
        self.active = True
        self._activate()
        if not self._autostarting:
            self.get_logger().info('activated: acting')
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop acting; configured still (activate resumes on the same publishers)."""
        self._deactivate()
        self.active = False
        self.get_logger().info('deactivated: not acting until activated again')
        return SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Back to unconfigured: the checkpoint and the data path are let go of."""
        self._release()
        self.configured = False
        self.get_logger().info('cleaned up: unconfigured')
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Finalized: stop acting and let go of everything configure took."""
        if self.active:
            self._deactivate()
            self.active = False
        if self.configured:
            self._release()
            self.configured = False
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """A transition raised: let go of everything and go back to unconfigured."""
        self.active = False
        self._release()
        self.configured = False
        return SUCCESS

    def lifecycle_state(self) -> str:
        """The state's label ('unconfigured', 'inactive', 'active', 'finalized'): diagnostics."""
        return str(self._state_machine.current_state[1])

