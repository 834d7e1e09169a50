MODULE roboisf_egm
    ! roboisf online compensation over ABB Externally Guided Motion, path correction
    ! (docs/online.md, "ABB EGM"). Written for roboisf from ABB's Application manual
    ! "Externally Guided Motion" (EGMSetupUC, EGMActMove, EGMMoveL, EGMStop); not tried on a
    ! controller by roboisf's authors: check each instruction against your RobotWare's manual.
    !
    ! Controller configuration (Communication > Transmission Protocol): a UDPUC device named
    ! ROBOISF, Remote Address and Remote Port the PC that runs
    !     roboisf online -c egm --path-correction --listen 0.0.0.0:6510 ...
    !
    ! The sensor frame: EGMActMove's second argument places it on the tool. Here it is the
    ! tool's own frame (tool_isf.tframe): the sensor frame is the TCP frame, and roboisf
    ! sends EgmSensorPathCorr.pathCorr.pos in it (the work-axes correction turned with the
    ! TCP's planned orientation of each EgmRobot message). tool_isf must be the tool of
    ! roboisf's study (its tool length: the TCP at the ball's centre), wobj_part the part's
    ! work object (roboisf's work frame).

    PERS tooldata tool_isf := [TRUE, [[0, 0, 250], [1, 0, 0, 0]], [3, [0, 0, 100], [1, 0, 0, 0], 0, 0, 0]];
    PERS wobjdata wobj_part := [FALSE, TRUE, "", [[1500, 0, 500], [1, 0, 0, 0]], [[0, 0, 0], [1, 0, 0, 0]]];
    VAR egmident egm_id;
    ! the EGM cycle, ms (roboisf online --cycle, default 4)
    CONST num EGM_SAMPLE_MS := 4;

    PROC roboisf_form()
        EGMReset egm_id;
        EGMGetId egm_id;
        ! path correction through the UDPUC device ROBOISF (\APTR: the corrections are
        ! applied along the programmed path)
        EGMSetupUC ROB_1, egm_id, "default", "ROBOISF" \PathCorr \APTR;
        EGMActMove egm_id, tool_isf.tframe \SampleRate:=EGM_SAMPLE_MS;
        ! the forming toolpath: every EGMMoveL is corrected by roboisf each EGM cycle
        ! (write the moves with `roboisf program`, then turn MoveL into EGMMoveL egm_id, ...)
        roboisf_toolpath;
        ! roboisf ramps its correction to zero when it stops; EGMStop ends the correction
        EGMStop egm_id, EGM_STOP_HOLD;
    ENDPROC

    PROC roboisf_toolpath()
        ! placeholder: the part's EGMMoveL moves, e.g.
        ! EGMMoveL egm_id, p10, v20, z1, tool_isf \WObj:=wobj_part;
    ENDPROC
ENDMODULE
