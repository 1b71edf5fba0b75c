MODULE humanpt_egm
    ! humanpt's EGM link: written by `humanpt robot-files` from [robot_gateway] (link "abb").
    ! Run humanpt_egm_run with the robot where the teaching or the playback begins: humanpt
    ! guides tool0 (the flange) in the base frame (EGM_FRAME_BASE) every 4 ms,
    ! the steps within [robot_gateway]'s limits (100 mm/s,
    ! 60 deg/s, the envelope), its target at most
    ! 5 mm / 2 deg ahead of the robot.
    VAR egmident egm_id;
    VAR egmstate egm_state;
    ! No correction beyond these from where EGM starts (mm, deg): a runaway stops here.
    CONST egm_minmax egm_xyz := [-1000, 1000];
    CONST egm_minmax egm_rot := [-45, 45];
    CONST pose corr_frame := [[0, 0, 0], [1, 0, 0, 0]];
    CONST pose sensor_frame := [[0, 0, 0], [1, 0, 0, 0]];

    PROC humanpt_egm_run()
        EGMReset egm_id;
        EGMGetId egm_id;
        egm_state := EGMGetState(egm_id);
        IF egm_state <= EGM_STATE_CONNECTED THEN
            ! UDP to the transmission protocol "HUMANPT" (humanpt_egm_sio.cfg), pose mode
            EGMSetupUC ROB_1, egm_id, "default", "HUMANPT" \Pose;
        ENDIF
        EGMActPose egm_id \Tool:=tool0 \WObj:=wobj0, corr_frame, EGM_FRAME_BASE, sensor_frame, EGM_FRAME_BASE
            \x:=egm_xyz \y:=egm_xyz \z:=egm_xyz \rx:=egm_rot \ry:=egm_rot \rz:=egm_rot
            \LpFilter:=20 \SampleRate:=4 \MaxPosDeviation:=1000 \MaxSpeedDeviation:=
            100;
        ! Until the operator stops the program, or 1 s without a message from humanpt.
        EGMRunPose egm_id, EGM_STOP_HOLD \x \y \z \Rx \Ry \Rz \CondTime:=1000000
            \RampInTime:=0.05 \RampOutTime:=0.5 \CommTimeout:=1;
        EGMReset egm_id;
    ERROR
        IF ERRNO = ERR_UDPUC_COMM THEN
            ! humanpt went silent (the communication timeout): the robot holds
            TPWrite "humanpt: no message from the gateway; EGM stopped";
            EGMReset egm_id;
            RETURN;
        ENDIF
    ENDPROC
ENDMODULE
